"""The one registry shape of every extension point (astaa_deft/model/registry.py)."""

from __future__ import annotations

import sys
import textwrap

import pytest

from astaa_deft.model.registry import DuplicateExtension, Registry


def test_a_file_dropped_into_the_package_registers_itself(tmp_path, monkeypatch):
    package = tmp_path / "throwaway_ext"
    package.mkdir()
    (package / "__init__.py").write_text(
        "from astaa_deft.model.registry import Registry\nR = Registry('thing', __name__)\n")
    (package / "base.py").write_text("raise AssertionError('base is not an extension')\n")
    (package / "alpha.py").write_text(textwrap.dedent("""
        from throwaway_ext import R
        @R.register_class
        class Alpha:
            name = "alpha"
    """))
    (package / "beta.py").write_text("from throwaway_ext import R\nR.register('beta', 2)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        import throwaway_ext
        assert throwaway_ext.R.names() == ("alpha", "beta")
        assert throwaway_ext.R["beta"] == 2
        assert "alpha" in throwaway_ext.R and "gamma" not in throwaway_ext.R
        assert throwaway_ext.R.get("gamma") is None
    finally:
        for name in [n for n in sys.modules if n.startswith("throwaway_ext")]:
            del sys.modules[name]


def test_two_extensions_of_one_name_are_refused():
    registry: Registry[int] = Registry("codec")
    registry.register("json", 1)
    registry.register("json", 1)  # the same object again (a module imported twice) is harmless
    with pytest.raises(DuplicateExtension, match="two codecs named 'json'"):
        registry.register("json", 2)
    registry.unregister("json")
    registry.register("json", 2)
    assert registry.names() == ("json",)
