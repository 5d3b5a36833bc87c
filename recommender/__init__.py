"""The recommender application of `active`: where to capture next (CLI recommend.py, docs/recommend.md).

For a trained model (a train.py model directory, read through `scene.trained.load_trained`, or a bare 3DGS PLY with
the views already taken), rank candidate camera poses that have no image yet:

- `pipeline.py`: `load_model` -> `candidate_cameras` -> `make_pool` -> `recommend` (the selection is
  `active.acquisition`'s, the same call train.py's acquisition stage makes);
- `candidates.py`: generated poses (`orbit:N`, `hemisphere:N`) around the captured views;
- `outputs.py`: the output folder (recommendations.json, transforms.json, previews, top-down picture).
"""
