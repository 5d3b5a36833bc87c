"""The training application of `active`: the 3DGS training engine with acquisition stages (CLI train.py).

`engine.py` runs a run (open or resume, train each stage, acquire, finish) from its pieces: `config.py` (flags,
validated), `state.py` (what a checkpoint holds), `step.py` (one training step), `acquisition.py` (seed views and
`acquire_views`, the stage's call of `active.acquisition.run_selection`), `optim.py` (Adam and the position learning
rate), `densify.py` and `param_ops.py` (densification, parameter surgery), `time_estimate.py` (the wall-time
estimate)."""
