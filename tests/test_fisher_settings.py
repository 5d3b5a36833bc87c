"""FisherSettings is built one way from train.py's config and from a model directory's recorded config."""
from active.acquisition import FisherSettings
from arguments import ActiveConfig


def test_active_config_defaults_are_the_fisher_defaults():
    assert FisherSettings.from_active(ActiveConfig()) == FisherSettings()


def test_recorded_config_maps_names_and_fills_defaults():
    recorded = {"sigma": 2.0, "fisher_params": "means", "fisher_mode": "streaming", "method": "lite_gs"}
    got = FisherSettings.from_active(recorded)
    assert got == FisherSettings(sigma=2.0, param_groups="means", mode="streaming")
    assert FisherSettings.from_active({}) == FisherSettings()


def test_every_field_has_an_active_name():
    from dataclasses import fields
    assert set(FisherSettings.ACTIVE_NAMES) == {f.name for f in fields(FisherSettings)}
    assert all(hasattr(ActiveConfig(), a) for a in FisherSettings.ACTIVE_NAMES.values())
