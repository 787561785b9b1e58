"""The strain's order amplitudes against wave-generator speed over the device population: the
paper's Fig. 2 as a population figure, and the sentence that says how often order 4 leads.

The amplitudes are simulator output, not a method's: ``rippleb report`` re-simulates the
public scenarios ``speed-sweep`` and ``paper-quintic`` on the run's seeds (``same-session``)
and measures each device's strain as the paper did (:mod:`rippleb.simulator.spectrum`),
as it re-simulates seeds for the other signal figures. Nothing of it is read from the rows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rippleb.report.plotting import _pyplot, _save
from rippleb.simulator import spectrum

#: The orders the figure draws in colour: the paper's three lines.
PAPER_ORDERS = {4: "#d62728", 2: "#1f77b4", 8: "#2ca02c"}


def population(seeds, condition: str = "same-session") -> dict:
    """``{scenario: (len(seeds), bands, orders)}``: each device's band amplitudes [V] on each
    scenario of :data:`~rippleb.simulator.spectrum.SCENARIOS`."""
    return {name: np.array([spectrum.case_bands(int(seed), name, condition) for seed in seeds])
            for name in spectrum.SCENARIOS}


def band_label(band) -> str:
    return f"{band[0]:g}-{band[1]:g}"


def fraction_sentence(cases: dict, bands=spectrum.SPEED_BANDS) -> str:
    """Per scenario and band of wave-generator speed: the devices whose largest strain line
    is order 4, of those with a window in the band."""
    out = []
    for name, per_device in cases.items():
        tops = np.array([spectrum.largest_order(b) for b in per_device])
        parts = []
        for i, band in enumerate(bands):
            seen = tops[:, i] > 0
            if seen.any():
                parts.append(f"{band_label(band)} rev/s {int((tops[seen, i] == 4).sum())}/{int(seen.sum())}")
        out.append(f"`{name}` " + (", ".join(parts) if parts else "no window"))
    return "order 4 the largest line on " + "; ".join(out)


def plot_orders_vs_speed(cases: dict, out_path, devices_text: str, bands=spectrum.SPEED_BANDS) -> Path:
    """Median over the cases (a device on a scenario) of each order's strain amplitude per
    band of wave-generator speed (orders 2, 4, 8 in colour with their inter-quartile range,
    the others grey), and beside it the share of cases whose largest line is each order."""
    plt = _pyplot()
    per_device = np.concatenate(list(cases.values()))
    centres = np.array([0.5 * (lo + hi) for lo, hi in bands])
    mv = 1e3 * per_device
    fig, (ax, bar) = plt.subplots(1, 2, figsize=(11, 4.5), gridspec_kw={"width_ratios": [3, 2]})
    for j, order in enumerate(spectrum.ORDERS):
        with np.errstate(all="ignore"):
            median = np.nanmedian(mv[:, :, j], axis=0)
        if order in PAPER_ORDERS:
            lo, hi = np.nanpercentile(mv[:, :, j], [25, 75], axis=0)
            ax.fill_between(centres, lo, hi, color=PAPER_ORDERS[order], alpha=0.15, lw=0)
            ax.plot(centres, median, "o-", color=PAPER_ORDERS[order], lw=2, label=f"order {order}")
        else:
            ax.plot(centres, median, "-", color="0.6", lw=0.8,
                    label="other orders (1-10)" if order == 1 else None)
    ax.set(yscale="log", xlabel="wave-generator speed [rev/s] (band centre)",
           ylabel="strain amplitude [mV] (0.1 V/Nm nominal)",
           title="median over devices, inter-quartile range shaded")
    ax.legend(fontsize=8, loc="center right")
    tops = np.array([spectrum.largest_order(b) for b in per_device])
    bottom = np.zeros(len(bands))
    for order in sorted(set(tops.ravel()) - {0}):
        seen = np.maximum((tops > 0).sum(axis=0), 1)
        share = (tops == order).sum(axis=0) / seen
        bar.bar(np.arange(len(bands)), share, bottom=bottom, color=PAPER_ORDERS.get(order, "0.6"),
                label=f"order {order}", edgecolor="white")
        bottom += share
    bar.set(xticks=np.arange(len(bands)), xticklabels=[band_label(b) for b in bands], ylim=(0, 1),
            xlabel="wave-generator speed [rev/s]", ylabel="share of devices",
            title="which order is the largest line (cases)")
    bar.legend(fontsize=8, loc="upper right")
    fig.suptitle(f"Strain re-sampled on the encoder (speed-sweep and paper-quintic, same-session), "
                 f"{devices_text}: the paper's Fig. 2 has order 4 the largest at every speed", fontsize=9)
    fig.tight_layout()
    return _save(fig, out_path)
