"""The project is an installable package: pyproject.toml lists every package, and nothing edits sys.path or loads
a script as a module (scripts, benchmarks and tests import the packages)."""
import re
import tomllib
from fnmatch import fnmatch
from pathlib import Path

from tests.conftest import ROOT


def _python_files() -> list:
    """The project's .py files (not this one, nothing under hidden folders or output/)."""
    return [p for p in ROOT.rglob("*.py") if not any(part.startswith(".") for part in p.relative_to(ROOT).parts)
            and p.relative_to(ROOT).parts[0] != "output" and p.resolve() != Path(__file__).resolve()]


def test_pyproject_includes_every_package():
    include = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]["include"]
    packages = sorted(p.parent.relative_to(ROOT).as_posix().replace("/", ".") for p in ROOT.glob("*/**/__init__.py")
                      if not p.relative_to(ROOT).parts[0].startswith("."))
    assert packages, "no packages found"
    missing = [name for name in packages if not any(fnmatch(name, pattern) for pattern in include)]
    assert not missing, f"packages not in pyproject.toml's include: {missing}"


def test_no_sys_path_edits_and_no_scripts_loaded_as_modules():
    edits = [str(p.relative_to(ROOT)) for p in _python_files() if re.search(r"sys\.path\.(insert|append)|sys\.path\s*=",
                                                                            p.read_text())]
    assert not edits, f"sys.path edited in {edits}; import the packages instead"
    loaders = [str(p.relative_to(ROOT)) for p in _python_files()
               if "spec_from_file_location" in p.read_text() or re.search(r"^\s*import train\b", p.read_text(), re.M)]
    assert not loaders, f"a script loaded as a module in {loaders}; move the code into a package"
