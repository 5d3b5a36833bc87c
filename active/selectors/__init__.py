"""One module per selector; each registers itself with `active.registry.register_selector`."""
