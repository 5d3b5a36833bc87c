"""Camera poses for a folder of photographs: COLMAP structure-from-motion on the CPU, in graphdeco's layout.

    DATA/input/*.jpg  ->  DATA/sparse/0/{cameras,images,points3D}.bin   (undistorted, PINHOLE)
                          DATA/images/ (undistorted), DATA/images_2/, images_4/, images_8/ (downscaled)
                          DATA/distorted/{database.db, sparse/0, logs/}   (COLMAP's own model and logs)
                          DATA/convert.json                               (steps, seconds, counts)

Steps (COLMAP 3.8 command-line tools): feature_extractor (one shared camera, SIMPLE_RADIAL by default, SIFT on
the CPU), exhaustive_matcher or sequential_matcher (no loop detection: its vocabulary tree is a download),
mapper, image_undistorter. Everything is built in DATA/.convert_tmp and moved into place only after every step
succeeded, so a failed run never leaves anything that looks like a finished `sparse/0`.
"""
from __future__ import annotations

import logging
import os
import re
import shutil
import subprocess
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from PIL import Image
from tqdm import tqdm

from scene import colmap_io
from scene.frames import IMAGE_SUFFIXES
from utils.errors import UserError
from utils.io import write_json

log = logging.getLogger(__name__)

EXHAUSTIVE_MAX_IMAGES = 60  # --matcher auto: exhaustive up to this many images (n^2/2 pairs), sequential above
DOWNSCALES = (2, 4, 8)
TMP = ".convert_tmp"
CAMERA_MODELS = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV")
INSTALL_HINT = "install it with: bash scripts/install_colmap.sh (Debian/Ubuntu, as root), or see " \
               "https://colmap.github.io/install.html"
_PROGRESS = re.compile(r"\[(\d+)/(\d+)")  # "Processed file [12/292]", "Matching image [3/40]", "Matching block [1/2,"
_REGISTERING = re.compile(r"Registering image #\d+")


@dataclass(frozen=True)
class ConvertOptions:
    """How convert.py runs COLMAP."""

    matcher: str = "auto"  # auto | exhaustive | sequential
    overlap: int = 10  # sequential matching: each image is matched with this many following ones
    camera_model: str = "SIMPLE_RADIAL"
    max_image_size: int = 0  # feature extraction downscales images larger than this (px); 0 = COLMAP's 3200
    max_num_features: int = 8192  # SIFT features per image (COLMAP's default)
    threads: int = -1  # COLMAP threads per step; -1 = all cores
    allow_partial: bool = False  # continue with the registered images when some are not registered
    colmap: str = "colmap"  # executable name or path


@dataclass
class StepRecord:
    """One COLMAP step of a conversion, for the progress lines and convert.json."""

    name: str
    seconds: float
    command: list[str] = field(default_factory=list)


@dataclass
class ConvertResult:
    """What a conversion produced."""

    num_input: int
    num_registered: int
    unregistered: list[str]
    mean_reprojection_error: float  # px, COLMAP's model_analyzer on the (distorted) model
    num_points: int
    matcher: str
    steps: list[StepRecord]
    seconds: float


def list_images(folder: Path) -> list[Path]:
    """Image files (png/jpg/jpeg, any case) directly in `folder`, sorted by name (the capture order)."""
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def prepare_input(data: Path) -> Path:
    """The folder of the photographs: DATA/input, or DATA/images renamed to DATA/input (its files are kept there).

    The undistorted images are written to DATA/images, so the originals must live elsewhere first.
    """
    if not data.is_dir():
        raise UserError(f"{data} is not a directory; pass -s with a folder holding input/ or images/ (photographs)")
    src = data / "input"
    if list_images(src):
        return src
    images = data / "images"
    if list_images(images) and not (data / "sparse" / "0").is_dir():
        if src.exists():
            if any(src.iterdir()):
                raise UserError(f"{src} exists but holds no .png/.jpg images, and {images} has the photographs; "
                                "move them into input/ (or remove input/)")
            src.rmdir()
        images.rename(src)
        log.info("convert: moved the photographs %s -> %s (the originals; undistorted images go to images/)",
                 images, src)
        return src
    raise UserError(f"no images (.png/.jpg/.jpeg) in {src} or {images}; put the photographs in {src}")


def find_colmap(colmap: str) -> str:
    """Full path of the COLMAP executable (UserError naming the install script when it is missing)."""
    path = shutil.which(colmap)
    if path is None:
        raise UserError(f"COLMAP not found ({colmap!r} is not on PATH); {INSTALL_HINT}")
    return path


def choose_matcher(matcher: str, num_images: int) -> str:
    """`exhaustive` or `sequential`; `auto` picks exhaustive for <= EXHAUSTIVE_MAX_IMAGES images."""
    if matcher not in ("auto", "exhaustive", "sequential"):
        raise UserError(f"--matcher must be auto, exhaustive or sequential, got {matcher!r}")
    if matcher != "auto":
        return matcher
    return "exhaustive" if num_images <= EXHAUSTIVE_MAX_IMAGES else "sequential"


def _tail(path: Path, n: int = 5) -> str:
    lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()] if path.is_file() else []
    return " | ".join(lines[-n:]) or "(empty log)"


def _line_buffered(command: list[str]) -> list[str]:
    """`command` under `stdbuf -oL` where coreutils has it: COLMAP block-buffers its progress lines into a pipe."""
    stdbuf = shutil.which("stdbuf")
    return [stdbuf, "-oL", "-eL", *command] if stdbuf else command


def run_step(name: str, command: list[str], log_path: Path, total: int | None = None) -> StepRecord:
    """Run one COLMAP command, its output to `log_path`, a progress bar from its `[i/n]` lines; UserError on failure."""
    log.info("convert: %s ...", name)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with open(log_path, "w") as fh, tqdm(total=total, desc=f"  {name}", unit="step", leave=False,
                                         disable=None) as bar:
        fh.write(" ".join(command) + "\n")
        fh.flush()
        try:
            proc = subprocess.Popen(_line_buffered(command), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    text=True, errors="replace")
        except OSError as exc:
            raise UserError(f"cannot run COLMAP ({command[0]}): {exc}; {INSTALL_HINT}") from exc
        assert proc.stdout is not None
        try:
            for line in proc.stdout:
                fh.write(line)
                m = _PROGRESS.search(line)
                if m:
                    bar.total = int(m.group(2))
                    bar.n = int(m.group(1))
                    bar.refresh()
                elif _REGISTERING.search(line):
                    bar.update(1)
        except BaseException:  # e.g. Ctrl-C: do not leave COLMAP running
            proc.kill()
            raise
        code = proc.wait()
    seconds = time.perf_counter() - start
    if code != 0:
        raise UserError(f"COLMAP {command[1]} failed (exit status {code}) after {seconds:.0f} s; last lines of "
                        f"{log_path}: {_tail(log_path)}")
    log.info("convert: %s done in %.1f s", name, seconds)
    return StepRecord(name, round(seconds, 2), command)


def model_stats(colmap: str, model: Path, log_path: Path) -> tuple[int, float, int]:
    """(registered images, mean reprojection error in px, 3D points) of a COLMAP model, from model_analyzer."""
    out = subprocess.run([colmap, "model_analyzer", "--path", str(model)], capture_output=True, text=True,
                         errors="replace")
    text = out.stdout + out.stderr
    log_path.write_text(text)
    found = {}
    for key, pattern in (("registered", r"Registered images:\s*(\d+)"), ("points", r"Points:\s*(\d+)"),
                         ("error", r"Mean reprojection error:\s*([0-9.eE+-]+)")):
        m = re.search(pattern, text)
        if m is None:
            raise UserError(f"COLMAP model_analyzer gave no '{key}' for {model}; see {log_path}")
        found[key] = m.group(1)
    return int(found["registered"]), float(found["error"]), int(found["points"])


def largest_model(sparse_root: Path) -> tuple[Path, list[str]] | None:
    """The mapper's model with the most registered images and their names (None when it made none)."""
    best = None
    for sub in sorted(p for p in sparse_root.iterdir() if p.is_dir()) if sparse_root.is_dir() else []:
        try:
            _, images, _ = colmap_io.read_model(sub)
        except UserError:
            continue
        names = sorted(im.name for im in images.values())
        if best is None or len(names) > len(best[1]):
            best = (sub, names)
    return best


def write_downscaled(images: Path, data_out: Path, factors: tuple[int, ...] = DOWNSCALES) -> None:
    """images_<f>/ beside `images`: every image resized to round(w/f) x round(h/f) (Lanczos), same file name."""
    files = list_images(images)
    for f in factors:
        (data_out / f"images_{f}").mkdir(parents=True, exist_ok=True)
    for path in tqdm(files, desc="  images_2/4/8", unit="img", leave=False, disable=None):
        with Image.open(path) as im:
            im.load()
            for f in factors:
                size = (max(1, round(im.width / f)), max(1, round(im.height / f)))
                im.resize(size, Image.LANCZOS).save(data_out / f"images_{f}" / path.name, quality=95)


def convert(data: Path, opts: ConvertOptions) -> ConvertResult:
    """Run COLMAP on DATA/input (or DATA/images) and write the graphdeco layout (see the module docstring)."""
    if opts.camera_model not in CAMERA_MODELS:
        raise UserError(f"--camera_model must be one of {', '.join(CAMERA_MODELS)}, got {opts.camera_model!r}")
    if opts.overlap < 1 or opts.max_image_size < 0 or opts.max_num_features < 1 or opts.threads == 0:
        raise UserError("--overlap and --max_num_features must be >= 1, --max_image_size >= 0 and --threads "
                        "-1 (all cores) or >= 1")
    colmap = find_colmap(opts.colmap)
    src = prepare_input(data)
    inputs = list_images(src)
    matcher = choose_matcher(opts.matcher, len(inputs))
    log.info("convert: %d images in %s; matcher %s%s", len(inputs), src, matcher,
             f" (overlap {opts.overlap})" if matcher == "sequential" else "")
    tmp = data / TMP
    if tmp.exists():
        shutil.rmtree(tmp)
    (tmp / "distorted" / "sparse").mkdir(parents=True)
    db, logs = tmp / "distorted" / "database.db", tmp / "distorted" / "logs"
    threads = str(opts.threads)
    start = time.perf_counter()
    steps = []
    extract = [colmap, "feature_extractor", "--database_path", str(db), "--image_path", str(src),
               "--ImageReader.single_camera", "1", "--ImageReader.camera_model", opts.camera_model,
               "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", threads,
               "--SiftExtraction.max_num_features", str(opts.max_num_features)]
    if opts.max_image_size:
        extract += ["--SiftExtraction.max_image_size", str(opts.max_image_size)]
    steps.append(run_step("1/4 feature extraction", extract, logs / "feature_extractor.log", len(inputs)))
    match = [colmap, f"{matcher}_matcher", "--database_path", str(db), "--SiftMatching.use_gpu", "0",
             "--SiftMatching.num_threads", threads]
    if matcher == "sequential":
        match += ["--SequentialMatching.overlap", str(opts.overlap), "--SequentialMatching.loop_detection", "0"]
    steps.append(run_step(f"2/4 matching ({matcher})", match, logs / f"{matcher}_matcher.log"))
    mapper = [colmap, "mapper", "--database_path", str(db), "--image_path", str(src),
              "--output_path", str(tmp / "distorted" / "sparse"), "--Mapper.num_threads", threads,
              "--Mapper.ba_global_function_tolerance", "0.000001"]  # graphdeco's setting: faster global BA
    steps.append(run_step("3/4 mapping", mapper, logs / "mapper.log", len(inputs)))
    best = largest_model(tmp / "distorted" / "sparse")
    if best is None:
        raise UserError(f"COLMAP registered none of the {len(inputs)} images (the mapper made no model): the photos "
                        f"may overlap too little or lack texture; see {logs / 'mapper.log'}")
    model, names = best
    registered, error, points = model_stats(colmap, model, logs / "model_analyzer.log")
    unregistered = sorted({p.name for p in inputs} - set(names))
    if unregistered:
        shown = ", ".join(unregistered[:5]) + (", ..." if len(unregistered) > 5 else "")
        msg = f"COLMAP registered {registered} of {len(inputs)} images; {len(unregistered)} not registered ({shown})"
        if not opts.allow_partial:
            raise UserError(f"{msg}; rerun with --allow_partial to continue with the registered ones, or add "
                            "photographs that overlap them")
        log.warning("convert: %s; continuing with the registered ones (--allow_partial)", msg)
    undistort = [colmap, "image_undistorter", "--image_path", str(src), "--input_path", str(model),
                 "--output_path", str(tmp / "undistorted"), "--output_type", "COLMAP"]
    steps.append(run_step("4/4 undistortion", undistort, logs / "image_undistorter.log", registered))
    sparse0 = tmp / "sparse" / "0"
    sparse0.mkdir(parents=True)
    for f in (tmp / "undistorted" / "sparse").iterdir():
        if f.is_file():
            f.rename(sparse0 / f.name)
    log.info("convert: writing images_2/4/8")
    t0 = time.perf_counter()
    write_downscaled(tmp / "undistorted" / "images", tmp)
    steps.append(StepRecord("downscaled images_2/4/8", round(time.perf_counter() - t0, 2)))
    chosen = tmp / "distorted" / "chosen"  # keep only the model used, as distorted/sparse/0 (graphdeco's layout)
    model.rename(chosen)
    shutil.rmtree(tmp / "distorted" / "sparse")
    (tmp / "distorted" / "sparse").mkdir()
    chosen.rename(tmp / "distorted" / "sparse" / "0")
    result = ConvertResult(len(inputs), registered, unregistered, error, points, matcher, steps,
                           round(time.perf_counter() - start, 2))
    _install(tmp, data)
    record = asdict(result)
    record.update(source=str(src), options=asdict(opts), colmap=colmap, model=model.name)
    write_json(data / "convert.json", record)
    return result


def _install(tmp: Path, data: Path) -> None:
    """Move the finished outputs from `tmp` into `data`, replacing an earlier conversion; sparse/ goes last."""
    if (data / "sparse").exists():
        shutil.rmtree(data / "sparse")  # first, so an interruption never pairs an old sparse/0 with new images
    (data / "convert.json").unlink(missing_ok=True)
    for name in ("distorted", "images", *(f"images_{f}" for f in DOWNSCALES)):
        target = data / name
        if target.exists():
            shutil.rmtree(target)
        source = tmp / "undistorted" / "images" if name == "images" else tmp / name
        os.replace(source, target)
    os.replace(tmp / "sparse", data / "sparse")
    shutil.rmtree(tmp)
