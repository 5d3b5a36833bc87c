"""Method specs NAME[+OPTION=VALUE...] of the experiment scripts (`experiments.method_spec`): parsed to the CLIs'
flags and to a selector with its options typed as the CLIs type them; a malformed spec or an unknown option is one error line."""
import re

import pytest

from experiments.method_spec import method_flags, parse_method_spec, selector_from_spec
from utils.errors import UserError


def test_a_spec_becomes_the_clis_flags():
    assert method_flags("pop_gs") == ["--method", "pop_gs"]
    assert method_flags("cover_pop+cover_gate=0.5") == ["--method", "cover_pop", "--cover_gate", "0.5"]
    assert parse_method_spec("novel_pop+novelty=1+gain_weight=opacity") == (
        "novel_pop", {"novelty": "1", "gain_weight": "opacity"})


def test_a_spec_builds_its_selector_with_typed_options():
    selector = selector_from_spec("cover_pop+cover_gate=0.5")
    assert selector.config.cover_gate == 0.5
    assert selector_from_spec("cover_pool+pool_weight=pixels").oracle_kind == "pool_coverage_pixels"
    assert selector_from_spec("cover_pool").oracle_kind == "pool_coverage"


@pytest.mark.parametrize("spec, message", [
    ("pop_gs+gain_weight", "write selector options as NAME+OPTION=VALUE"),
    ("cover_pool+pool_weight=area", "--pool_weight must be one of opacity, pixels"),
    ("cover_pool+eps=0.1", "has no option eps"),
    ("cover_pop+cover_gate=high", "--cover_gate takes a float, got 'high'"),
    ("no_such_selector", "no_such_selector"),
])
def test_bad_specs_are_one_error_line(spec, message):
    with pytest.raises(UserError, match=re.escape(message)):
        selector_from_spec(spec)
