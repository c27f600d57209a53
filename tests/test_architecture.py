"""The structure docs/architecture.md describes, kept true: the import-linter contracts in
pyproject.toml (the layers, no import circle, the NumPy reference out of the runtime path, the
config opening no recording) hold, and each source kind named in names.READERS has its reader."""

import importlib
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold():
    from importlinter.cli import lint_imports

    here = os.getcwd()
    os.chdir(ROOT)
    try:
        assert lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True) == 0, \
            "an import breaks a contract in pyproject.toml (run lint-imports to see which)"
    finally:
        os.chdir(here)


def test_a_contract_is_checked_not_assumed(tmp_path):
    """The linter fails a config whose layers are upside down (the check can fail)."""
    from importlinter.cli import lint_imports

    config = tmp_path / "upside_down.toml"
    config.write_text('[tool.importlinter]\nroot_package = "dpom_warp"\n\n[[tool.importlinter.contracts]]\n'
                      'name = "inverted"\ntype = "layers"\ncontainers = ["dpom_warp"]\n'
                      'layers = ["geometry", "cli"]\n')
    assert lint_imports(config_filename=str(config), no_cache=True) == 1


def test_every_source_kind_has_its_reader():
    from dpom_warp.names import READERS

    for kind, (_, module, name) in READERS.items():
        assert hasattr(importlib.import_module(f"dpom_warp.sources.{module}"), name), kind
