"""FisherSettings is one object from train.py's flags to the view blocks: built one way from train.py's config and
from a model directory's recorded config, with its defaults and names shared by ActiveConfig."""
from dataclasses import fields, replace

import pytest

from active.fisher import FISHER_PARAM_GROUPS, FisherViewBlocks
from arguments import ActiveConfig, FisherSettings


def test_active_config_defaults_are_the_fisher_defaults():
    assert FisherSettings.from_active(ActiveConfig()) == FisherSettings()
    custom = replace(ActiveConfig(), sigma=0.5, fisher_mode="streaming", fisher_cache_mb=7)
    assert FisherSettings.from_active(custom) == FisherSettings(sigma=0.5, fisher_mode="streaming", fisher_cache_mb=7)


def test_recorded_config_fills_defaults_and_ignores_other_names():
    recorded = {"sigma": 2.0, "fisher_params": "full_sh", "fisher_mode": "streaming", "method": "lite_gs"}
    got = FisherSettings.from_active(recorded)
    assert got == FisherSettings(sigma=2.0, fisher_params="full_sh", fisher_mode="streaming") and got.streaming
    assert FisherSettings.from_active({}) == FisherSettings() and not FisherSettings().streaming


def test_active_config_states_no_fisher_default_or_name_of_its_own():
    active = {f.name: f for f in fields(ActiveConfig)}
    for f in fields(FisherSettings):  # the same name, type, default, help and choices
        assert f.name in active, f.name
        assert (active[f.name].type, active[f.name].default, active[f.name].metadata) == (f.type, f.default,
                                                                                           f.metadata)
    assert set(active["fisher_params"].metadata["choices"]) == set(FISHER_PARAM_GROUPS)


@pytest.mark.parametrize("fisher, groups, streaming", [
    (FisherSettings(), FISHER_PARAM_GROUPS["default"], False),
    (FisherSettings(fisher_params="full_sh", fisher_mode="streaming"), FISHER_PARAM_GROUPS["full_sh"], True)])
def test_the_view_blocks_take_the_settings_whole(monkeypatch, fisher, groups, streaming):
    monkeypatch.setattr("active.fisher.cache_budget", lambda cache_mb: cache_mb + 1)
    blocks = FisherViewBlocks(None, [], None, None, replace(fisher, fisher_cache_mb=5))
    assert (blocks.param_groups, blocks.streaming, blocks.cache_bytes) == (groups, streaming, 6)
