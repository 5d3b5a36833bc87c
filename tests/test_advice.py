"""recommender/advice.py: which selectors get which measured-evidence note (the path recommend.py records)."""
from active import build_selector
from recommender.advice import FEW_VIEWS, selection_advice


def test_geometric_selectors_say_their_picks_are_geometric():
    for name in ("cover_pool", "cover", "coverage"):
        note = selection_advice(build_selector(name), 5)
        assert "geometric" in note and "level with camera-centre coverage" in note


def test_random_gets_no_note():
    assert selection_advice(build_selector("random"), 5) is None


def test_fisher_selectors_are_warned_only_from_few_views():
    for name in ("pop_gs", "lite_gs", "lazy_pop", "render_variance", "novel_pop"):
        note = selection_advice(build_selector(name), 5)
        assert note.startswith("note: 5 captured views") and "--method coverage " in note
        assert selection_advice(build_selector(name), FEW_VIEWS + 1) is None
