"""The recommend-then-train tables of docs/recommend.md, generated from the committed results.json files.

    python scripts/recommend_tables.py            # exit 1 and name the stale tables if the docs differ
    python scripts/recommend_tables.py --write    # rewrite them (and each folder's summary.md)

Each scene's table (every method in its results.json, in the order they were run), the cross-scene comparison
(`experiments.recommend_train_loop.compare_table`) and the cached-vs-streaming timing table (`modes_table`, from the
recommendations.json files in docs/results/recommend_modes) sit in docs/recommend.md between
`<!-- generated: NAME -->` and `<!-- end generated -->` lines; tests/test_docs_tables.py checks that they are what
this script writes.
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from experiments.recommend_train_loop import compare_table, recorded_runs, summary_table
from utils.errors import UserError, run_cli
from utils.io import read_json

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "recommend.md"
SCENES = (("lego", "rtt_lego_official"), ("mic", "rtt_mic_official"), ("bonsai", "rtt_bonsai"))  # scene, folder
# Scenes no selector was designed on: the built-in scene and two `--layout clutter` scenes (scene/clutter.py)
HELDOUT = (("built-in", "rtt_builtin_1206"), ("clutter 1", "rtt_clutter1"), ("clutter 2", "rtt_clutter2"))
# The design scenes again with the seed views drawn per seed (--seed_start random): every selector's seeds are
# different view sets, a deterministic one's too
DRAWN = (("lego", "rtt_rstart_lego"), ("mic", "rtt_rstart_mic"), ("bonsai", "rtt_rstart_bonsai"),
         ("bonsai, SfM of 12-07", "rtt_rstart_bonsai_sfm1207"))  # bonsai again on a second COLMAP reconstruction
# The drawn-seed scenes on which cover ran too (the first bonsai reconstruction was gone by then): cover compared
DRAWN_WITH_COVER = (DRAWN[0], DRAWN[1], DRAWN[3])
HELDOUT_DRAWN = (("clutter 3", "rtt_rstart_clutter3"), ("clutter 4", "rtt_rstart_clutter4"))  # and two held-out scenes
# Held out from the default too (generated after auto and the default were fixed), with its baselines only: a table
# of its own, in no comparison
DEFAULT_CHECKS = (("clutter 4", "rtt_clutter4"),)
COMPARE, COMPARE_HELDOUT = "rtt_compare", "rtt_compare_heldout"
COMPARE_DRAWN, COMPARE_HELDOUT_DRAWN = "rtt_compare_rstart", "rtt_compare_rstart_heldout"
COMPARE_DRAWN_COVER = "rtt_compare_rstart_cover"
# Each comparison block with the scene tables it compares, and every folder that gets a table of its own
GROUPS = ((SCENES, COMPARE), (HELDOUT, COMPARE_HELDOUT), (DRAWN, COMPARE_DRAWN),
          (HELDOUT_DRAWN, COMPARE_HELDOUT_DRAWN), (DRAWN_WITH_COVER, COMPARE_DRAWN_COVER))
FOLDERS = tuple(dict.fromkeys([folder for scenes, _ in GROUPS for _, folder in scenes]
                              + [folder for _, folder in DEFAULT_CHECKS]))
BLOCK = re.compile(r"(<!-- generated: (\S+) -->\n)(.*?)(<!-- end generated -->)", re.S)
BASELINES = ("coverage", "cover", "random")  # the first rows of every table, then the others in the order they ran
MODES = "recommend_modes"  # folder of recommendations.json files, MODE_SELECTOR.json: the cached-vs-streaming table
MODE_ORDER, SELECTOR_ORDER = ("cached", "streaming"), ("lite_gs", "lazy_pop", "pop_gs")


def scene_summary(results: dict) -> str:
    """summary_table over every method and seed of one results.json: the baselines first, then the other methods in
    the order they were run."""
    run_order, seeds = recorded_runs(results)
    methods = [m for m in BASELINES if m in run_order] + [m for m in run_order if m not in BASELINES]
    return summary_table(results, methods, seeds)


def modes_table(folder: Path) -> str:
    """The cached-vs-streaming table from recommend.py's recommendations.json files named MODE_SELECTOR.json: per
    run its oracle counts, distinct candidate views computed, seconds and picks, and its total time over pop_gs's in
    the same mode. Options left at "none" are not shown."""
    runs = {}
    for path in sorted(folder.glob("*.json")):
        rec = read_json(path, what="recommend.py output", fix="copy a run's recommendations.json here")
        runs[(rec["settings"]["fisher"]["fisher_mode"], rec["selector"])] = rec
    order = lambda key: (MODE_ORDER.index(key[0]), SELECTOR_ORDER.index(key[1]) if key[1] in SELECTOR_ORDER else 99)
    lines = ["| Fisher mode | selector | oracles evaluated / conservative | views computed | Fisher s | gain s | "
             "**total s** | / pop_gs | picks |", "|---|---|---|---|---|---|---|---|---|"]
    for mode, selector in sorted(runs, key=order):
        rec, base = runs[(mode, selector)], runs.get((mode, "pop_gs"))
        options = ", ".join(f"{k} = {v}" for k, v in rec["selector_options"].items() if v != "none")
        ratio = f"{rec['seconds']['total'] / base['seconds']['total']:.2f}×" if base and selector != "pop_gs" else ""
        calls, sec = rec["oracle_calls"], rec["seconds"]
        lines.append(f"| {mode} | {selector}{' ' + options if options else ''} | {calls['evaluated']} / "
                     f"{calls['conservative']} | {rec['fisher_views_computed']} | {sec['fisher']:.1f} | "
                     f"{sec['gain']:.1f} | **{sec['total']:.1f}** | {ratio} | "
                     f"{', '.join(str(p['candidate']) for p in rec['picks'])} |")
    return "\n".join(lines) + "\n"


def scene_results(results_dir: Path, folder: str) -> dict:
    """A scene folder's committed recommend-then-train results.json, every method on every seed finished."""
    path = results_dir / folder / "results.json"
    results = read_json(path, what="recommend-then-train results", fix="run scripts/recommend_then_train.py")
    methods, seeds = recorded_runs(results)
    missing = [f"{m}/seed{x}" for m in methods for x in seeds if "test_psnr" not in results.get(f"{m}/seed{x}", {})]
    if missing:
        raise UserError(f"{path} has no finished run for {', '.join(missing)}: finish them with "
                        "scripts/recommend_then_train.py (a table needs every method on every seed)")
    return results


def generated_blocks(results_dir: Path = ROOT / "docs" / "results") -> dict[str, str]:
    """Block name -> its text: one per scene folder, the comparisons across the design scenes and across the
    held-out ones (the default's own checks in none), and (where its folder is there) the cached-vs-streaming
    table."""
    loaded = {folder: scene_results(results_dir, folder) for folder in FOLDERS}  # each folder read once
    blocks = {folder: scene_summary(results) for folder, results in loaded.items()}
    for scenes, compare in GROUPS:
        blocks[compare] = compare_table({scene: loaded[folder] for scene, folder in scenes})
    if (results_dir / MODES).is_dir():
        blocks[MODES] = modes_table(results_dir / MODES)
    return blocks


def splice(doc: str, blocks: dict[str, str]) -> str:
    """`doc` with each generated block's body replaced by `blocks[name]` (blocks absent from `blocks` kept)."""
    return BLOCK.sub(lambda m: m.group(1) + blocks.get(m.group(2), m.group(3)) + m.group(4), doc)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--write", action="store_true", help="rewrite docs/recommend.md's tables and the summary.md files")
    args = p.parse_args(argv)
    blocks = generated_blocks()
    doc = DOC.read_text()
    names = {m.group(2) for m in BLOCK.finditer(doc)}
    missing = sorted(set(blocks) - names)
    if missing:
        print(f"error: docs/recommend.md has no generated block for {', '.join(missing)}", file=sys.stderr)
        return 1
    new = splice(doc, blocks)
    if args.write:
        DOC.write_text(new)
        for folder in FOLDERS:
            (ROOT / "docs" / "results" / folder / "summary.md").write_text(blocks[folder])
        print(f"wrote {DOC.relative_to(ROOT)} and {len(FOLDERS)} summary.md files")
        return 0
    if new != doc:
        print("docs/recommend.md's recommend-then-train tables are stale: run python scripts/recommend_tables.py "
              "--write", file=sys.stderr)
        return 1
    print("docs/recommend.md's recommend-then-train tables match the committed results")
    return 0


if __name__ == "__main__":
    run_cli(main)
