"""Built-in method plugins of rippleb, one module per method family (installed as rippleb.methods)."""
