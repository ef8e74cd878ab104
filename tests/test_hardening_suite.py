"""An exported DeFT suite runs the same wherever it is written:
inside a project whose pytest settings need plugins the user lacks, pytest must
still take the suite's own configuration."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.analysis.deft.export import export_suite
from astaa_deft.engine.spec.loader import load_spec

HOSTILE_PYPROJECT = """\
[tool.pytest.ini_options]
addopts = "--no-such-option-from-the-enclosing-project=300 -m 'not slow'"
testpaths = ["tests"]
"""


def test_suite_inside_a_hostile_project_uses_its_own_config(tmp_path: Path):
    project = tmp_path / "checkout"
    (project / "tests").mkdir(parents=True)
    (project / "pyproject.toml").write_text(HOSTILE_PYPROJECT)
    (project / "conftest.py").write_text("raise RuntimeError('the enclosing project conftest must not load')\n")
    suite = project / "astaa-deft-demo" / "planner-tests"
    export_suite([], load_spec(demo_spec_path()), {"scenario": "lane_follow", "defects": "off"}, suite)
    # As the demo's step 2 runs it (cwd = the demo's output directory), and as a user would from the checkout.
    for cwd in (suite.parent, project):
        res = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", str(suite)],
                             capture_output=True, text=True, cwd=cwd, timeout=120)
        text = res.stdout + res.stderr
        assert "unrecognized arguments" not in text and "RuntimeError" not in text, text
        assert res.returncode == 5, text  # collected the suite's manifest; an empty suite runs no test
        assert f"rootdir: {suite}" in text, text
