"""Live 3D viewer of a trained model in the browser (viser): the Gaussians as splats, the cameras as frusta in the
colours of the run's report (seed views, each stage's picks numbered, candidates, test cameras); click a camera
to see its image, a render from it and its uncertainty map of one kind (render.py --uncertainty).

    python view.py -m output/lego              # prints http://localhost:PORT; Ctrl-C stops it
    python view.py -m output/lego --port 8090  # a port in use: the next free one is taken, and said
    python view.py -m output/lego --uncertainty_kind position_variance
"""
from __future__ import annotations

import argparse
import logging
import threading

from utils.errors import UserError, run_cli


def main(argv: list[str] | None = None) -> int:
    """Load the model, serve it until Ctrl-C (SIGINT) or SIGTERM, stop cleanly."""
    import signal

    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model_path", required=True, help="model directory written by train.py")
    parser.add_argument("-s", "--source_path", default=None, help="dataset directory (default: the one in cfg_args)")
    parser.add_argument("--iteration", type=int, default=-1, help="saved iteration to show (-1 = the last)")
    parser.add_argument("--port", type=int, default=8080, help="port on localhost (default 8080; the next free one "
                                                                "when it is in use)")
    parser.add_argument("--uncertainty_kind", choices=("fisherrf_view", "fisherrf", "position_variance"),
                        default=None, help="uncertainty map kind shown (default: the first written of fisherrf_view, "
                                           "fisherrf, position_variance)")
    args = parser.parse_args(argv)
    if not 1 <= args.port <= 65535:
        raise UserError(f"--port must be in 1..65535, got {args.port}")
    from reports.viewer import Viewer
    from scene.trained import load_trained

    trained = load_trained(args.model_path, args.iteration, args.source_path, device="cpu")
    viewer = Viewer(trained, args.port, args.uncertainty_kind)
    if viewer.port != args.port:
        print(f"port {args.port} is in use; serving on port {viewer.port} instead")
    print(f"viewer of {args.model_path}: http://localhost:{viewer.port} (Ctrl-C stops it)", flush=True)

    @viewer.server.on_client_connect
    def _(client) -> None:
        print(f"client {client.client_id} connected", flush=True)

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):  # also when started with SIGINT ignored (a background job)
        signal.signal(sig, lambda *_: stop.set())
    while not stop.wait(0.5):
        pass
    viewer.stop()
    print("viewer stopped", flush=True)
    return 0


if __name__ == "__main__":
    run_cli(main)
