"""Built-in scenarios of rippleb, one TOML file each (installed as rippleb.scenarios)."""
