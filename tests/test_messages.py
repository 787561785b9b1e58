"""The messages a job sends the runner (rippleb/engine/cache.py): what goes in comes out bit
for bit, and bytes that are not a message of plain numbers are refused, never trusted."""

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra import numpy as hnp

from rippleb.engine.cache import RAW_MAGIC, pack_raw, unpack

DTYPES = st.sampled_from([np.float64, np.float32, np.int64, np.int32, np.uint8, np.bool_])
ARRAYS = DTYPES.flatmap(lambda dtype: hnp.arrays(dtype, hnp.array_shapes(min_dims=0, max_dims=2, min_side=0,
                                                                          max_side=20)))


@settings(max_examples=200, derandomize=True, deadline=None)
@given(st.dictionaries(st.text(min_size=1, max_size=8), ARRAYS, max_size=4),
       st.dictionaries(st.text(max_size=8), st.one_of(st.integers(), st.text(max_size=8), st.booleans())))
def test_a_message_returns_its_arrays_and_info_bit_for_bit(arrays, info):
    got, got_info = unpack(pack_raw(arrays, info))
    assert got_info == info and list(got) == list(arrays)
    for name, value in arrays.items():
        assert got[name].dtype == value.dtype and got[name].shape == value.shape
        assert got[name].tobytes() == value.tobytes()          # NaN payloads and signed zeros too
        assert got[name].flags.writeable and got[name].flags.owndata   # a copy, not a view of the message


def _message(entries, info=None, body=b"\0" * 256):
    header = json.dumps({"info": info or {}, "arrays": entries}).encode()
    head = RAW_MAGIC + len(header).to_bytes(4, "little") + header
    return head + b"\0" * (-len(head) % 64) + body


@pytest.mark.parametrize("entries", [
    [["x", "|O", [1], 0]],              # an object: what unpickling would need
    [["x", "V8", [1], 0]],               # raw records
    [["x", [["a", "<f8"]], [1], 0]],     # a structured dtype
    [["x", "<f8", [100], 0]],            # beyond the message's end
    [["x", "<f8", [-1], 0]],             # a negative length
    [["x", "<f8", [1], -64]],            # before its start
    [["x", "<f8", [1]]],                 # an entry cut short
])
def test_a_message_of_anything_but_plain_numbers_inside_it_is_refused(entries):
    with pytest.raises((ValueError, TypeError)):
        unpack(_message(entries))


def test_a_header_that_lies_about_its_length_or_shape_is_refused():
    with pytest.raises(ValueError):
        unpack(RAW_MAGIC + (10**6).to_bytes(4, "little") + b"{}")
    with pytest.raises(ValueError):
        unpack(_message([], info=None).replace(b'"arrays": []', b'"arrays": 3 '))
    with pytest.raises(ValueError):
        unpack(RAW_MAGIC[:-1])
