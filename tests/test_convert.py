"""convert.py: COLMAP on a small synthetic capture (skipped without COLMAP), and its bad-input paths with a fake
`colmap` executable (no COLMAP needed)."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.conftest import ROOT, run_cli

FAKE_COLMAP = r'''#!{python}
"""Stand-in for COLMAP: $FAKE_MODE = ok | fail_match | partial (the mapper leaves out the last image)."""
import os, shutil, sys
from pathlib import Path
cmd, args = sys.argv[1], sys.argv[2:]
opt = {{args[i]: args[i + 1] for i in range(0, len(args) - 1, 2)}}
mode = os.environ.get("FAKE_MODE", "ok")
if cmd == "feature_extractor":
    Path(opt["--database_path"]).write_text("db")
    print("Processed file [1/1]")
elif cmd.endswith("_matcher"):
    if mode == "fail_match":
        print("Matching block [1/1, 1/1]")
        print("F1201 fake matcher crash: out of memory")
        sys.exit(134)
elif cmd == "mapper":
    names = sorted(os.listdir(opt["--image_path"]))
    if mode == "partial":
        names = names[:-1]
    model = Path(opt["--output_path"]) / "0"
    model.mkdir(parents=True)
    (model / "cameras.txt").write_text("1 PINHOLE 40 30 50 50 20 15\n")
    (model / "images.txt").write_text("".join(f"{{i + 1}} 1 0 0 0 0 0 {{i}} 1 {{n}}\n\n" for i, n in enumerate(names)))
    (model / "points3D.txt").write_text("1 0 0 5 128 128 128 0.5\n")
elif cmd == "model_analyzer":
    n = sum(1 for ln in (Path(opt["--path"]) / "images.txt").read_text().splitlines() if ln.strip())
    print(f"Registered images: {{n}}\nPoints: 1\nMean reprojection error: 0.5px", file=sys.stderr)
elif cmd == "image_undistorter":
    out, model = Path(opt["--output_path"]), Path(opt["--input_path"])
    (out / "images").mkdir(parents=True)
    shutil.copytree(model, out / "sparse")
    for ln in (model / "images.txt").read_text().splitlines():
        if ln.strip():
            name = ln.split()[-1]
            shutil.copy(Path(opt["--image_path"]) / name, out / "images" / name)
'''


def fake_colmap(tmp: Path) -> dict[str, str]:
    """Environment with the fake `colmap` first on PATH."""
    bin_dir = tmp / "bin"
    bin_dir.mkdir()
    exe = bin_dir / "colmap"
    exe.write_text(FAKE_COLMAP.format(python=sys.executable))
    exe.chmod(0o755)
    return {"PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}


def photos(folder: Path, n: int = 3, size: tuple[int, int] = (40, 30)) -> list[str]:
    folder.mkdir(parents=True)
    names = [f"im_{i}.png" for i in range(n)]
    for i, name in enumerate(names):
        Image.fromarray(np.full((size[1], size[0], 3), 40 * i, np.uint8)).save(folder / name)
    return names


def convert(data: Path, *extra: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run convert.py with `env` added to the environment."""
    return subprocess.run([sys.executable, "convert.py", "-s", str(data), *extra], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


def assert_one_error(proc, *needles: str) -> None:
    assert proc.returncode != 0
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "Traceback" not in proc.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


def assert_nothing_finished(data: Path) -> None:
    assert not (data / "sparse").exists() and not (data / "images").exists()
    assert not (data / "convert.json").exists()


# ----------------------------------------------------------------------------------------------- bad input


def test_folder_without_images(tmp_path):
    (tmp_path / "d" / "input").mkdir(parents=True)
    (tmp_path / "d" / "input" / "notes.txt").write_text("x")
    assert_one_error(convert(tmp_path / "d", env=fake_colmap(tmp_path)), "no images")


def test_colmap_missing(tmp_path):
    photos(tmp_path / "d" / "input")
    proc = convert(tmp_path / "d", "--colmap_executable", "colmap-not-installed-here")
    assert_one_error(proc, "COLMAP not found", "scripts/install_colmap.sh")
    assert_nothing_finished(tmp_path / "d")


def test_step_failing_midway_leaves_no_model(tmp_path):
    data = tmp_path / "d"
    photos(data / "input")
    proc = convert(data, env={**fake_colmap(tmp_path), "FAKE_MODE": "fail_match"})
    assert_one_error(proc, "exhaustive_matcher failed", "exit status 134", "fake matcher crash")
    assert_nothing_finished(data)
    assert "1/4 feature extraction done" in proc.stdout


def test_unregistered_images_need_allow_partial(tmp_path):
    data = tmp_path / "d"
    names = photos(data / "input")
    env = {**fake_colmap(tmp_path), "FAKE_MODE": "partial"}
    assert_one_error(convert(data, env=env), "registered 2 of 3 images", "1 not registered (im_2.png)",
                     "--allow_partial")
    assert_nothing_finished(data)
    proc = convert(data, "--allow_partial", env=env)
    assert proc.returncode == 0, proc.stderr
    assert sorted(os.listdir(data / "images")) == names[:2]
    record = json.loads((data / "convert.json").read_text())
    assert (record["num_input"], record["num_registered"], record["unregistered"]) == (3, 2, ["im_2.png"])


def test_layout_and_images_folder_kept(tmp_path):
    """Photographs given as DATA/images end up in DATA/input; the graphdeco layout is written, images_N sized."""
    data = tmp_path / "d"
    names = photos(data / "images", n=3, size=(41, 30))
    proc = convert(data, "--matcher", "sequential", "--overlap", "4", env=fake_colmap(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert sorted(os.listdir(data / "input")) == names
    assert "registered 3 of 3 images, mean reprojection error 0.500 px" in proc.stdout
    for f, size in ((2, (20, 15)), (4, (10, 8)), (8, (5, 4))):  # round(41/f) x round(30/f)
        assert sorted(os.listdir(data / f"images_{f}")) == names
        assert Image.open(data / f"images_{f}" / names[0]).size == size
    assert sorted(os.listdir(data / "sparse" / "0")) == ["cameras.txt", "images.txt", "points3D.txt"]
    assert (data / "distorted" / "sparse" / "0" / "images.txt").is_file()
    assert not (data / ".convert_tmp").exists()
    record = json.loads((data / "convert.json").read_text())
    assert record["matcher"] == "sequential"
    assert [s["name"].split(" ", 1)[1] for s in record["steps"]] == [
        "feature extraction", "matching (sequential)", "mapping", "undistortion", "images_2/4/8"]
    match = record["steps"][1]["command"]
    assert match[match.index("--SequentialMatching.overlap") + 1] == "4"
    assert match[match.index("--SequentialMatching.loop_detection") + 1] == "0"


def test_matcher_choice():
    from scene.colmap_convert import choose_matcher
    assert choose_matcher("auto", 60) == "exhaustive"
    assert choose_matcher("auto", 61) == "sequential"
    assert choose_matcher("exhaustive", 500) == "exhaustive"


# ----------------------------------------------------------------------------------------------- real COLMAP


@pytest.mark.slow  # ~1 min on an idle 2-core machine (COLMAP on 8 images, a short train.py run)
@pytest.mark.skipif(shutil.which("colmap") is None,
                    reason="COLMAP not on PATH (bash scripts/install_colmap.sh installs it)")
def test_colmap_recovers_synthetic_capture(tmp_path):
    """COLMAP registers the textured box capture; centres match the truth up to a similarity; train.py runs."""
    from scene.dataset_readers import load_scene_info
    from tests.textured_capture import make_textured_capture
    data = tmp_path / "cap"
    truth = make_textured_capture(data / "input", num_views=8, width=240, height=180)
    proc = convert(data, "--threads", "1", "--max_num_features", "1500")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    record = json.loads((data / "convert.json").read_text())
    assert record["num_registered"] >= 7 and record["mean_reprojection_error"] < 1.0
    info = load_scene_info(str(data), images="images_2")
    cams = info.train_cameras
    full = Image.open(next((data / "images").iterdir())).size
    assert (cams[0].width, cams[0].height) == (round(full[0] / 2), round(full[1] / 2))
    got = np.stack([c.camera_center.double().numpy() for c in cams])  # [V,3]
    want = np.stack([truth[int(re.search(r"view_(\d+)", c.image_name).group(1))][1] for c in cams])  # [V,3]
    # similarity (Umeyama) from COLMAP's frame to the truth, residual relative to the spread of the centres
    g, w = got - got.mean(0), want - want.mean(0)
    u, s, vt = np.linalg.svd(w.T @ g)
    d = np.diag([1, 1, np.sign(np.linalg.det(u @ vt))])
    rot, scale = u @ d @ vt, (s * np.diag(d)).sum() / (g ** 2).sum()
    residual = np.linalg.norm(scale * g @ rot.T - w, axis=1).max()
    assert residual < 0.02 * np.linalg.norm(w, axis=1).max(), residual
    train = run_cli("train.py", "-s", str(data), "-m", str(tmp_path / "m"), "-i", "images_4", "--iterations", "20",
                    "--quiet", timeout=600)
    assert train.returncode == 0, train.stderr


def test_install_script_paths(tmp_path):
    """No-op when colmap is on PATH; a clear error when apt-get is missing (no install attempted)."""
    script = str(ROOT / "scripts" / "install_colmap.sh")
    bash = shutil.which("bash")
    env = fake_colmap(tmp_path)
    fake_bin = env["PATH"].split(os.pathsep)[0]
    done = subprocess.run([bash, script], capture_output=True, text=True, env={"PATH": fake_bin})
    assert done.returncode == 0 and "already on PATH" in done.stdout, done.stderr
    (tmp_path / "empty").mkdir()
    none = subprocess.run([bash, script], capture_output=True, text=True, env={"PATH": str(tmp_path / "empty")})
    assert none.returncode == 1 and "apt-get not available" in none.stderr
