"""The training engine (`engine.py`, driven by train.py) and its pieces: config, state, step, acquisition, the
optimiser and its schedule, densification, parameter surgery, the wall-time estimate."""
