"""Each command reads and validates the user's spec once in its own process, and hands the loaded spec down.

Every command that takes ``--spec`` runs here in this process on small
committed inputs (the zoo's mpc stack and its pinned log, tests/sut/steady.yaml,
the bundled demo's spec and test case) with the spec loader wrapped by a
counter that still runs the real loader: each command loads the spec exactly
once (worker processes, such as the pytest run an extraction checks its
suite with, load their own). A command that stops early (minimise on a run
without mutations, fuzz without its hunt) is counted up to where it stops.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from zoo import by_name, short, write_member

from astaa_deft.demo.bundled import demo_policy_path, demo_spec_path
from astaa_deft.engine.spec import loader
from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignResult, StopReason

from cli_in_process import run_in_process

PINNED = Path(__file__).parent / "data" / "extraction_pins" / "mpc" / "run.mcap"
STEADY = Path(__file__).parent / "sut" / "steady.yaml"


@pytest.fixture
def loads(monkeypatch: pytest.MonkeyPatch) -> Callable[..., tuple[int, list[str], str]]:
    """``run(*argv)``: the command's exit code, the spec files it loaded (in order) and what it printed on stderr."""
    real = loader.load_spec
    seen: list[str] = []

    def counting(path: Path | str):
        seen.append(str(path))
        return real(path)

    def run(*argv: str) -> tuple[int, list[str], str]:
        # every module that imported the loader by name, as its command imports it (late imports included)
        for module in list(sys.modules.values()):
            if getattr(module, "load_spec", None) is real:
                monkeypatch.setattr(module, "load_spec", counting)
        monkeypatch.setattr(loader, "load_spec", counting)
        seen.clear()
        code, err = run_in_process(*argv)
        return code, list(seen), err

    return run


@pytest.fixture(scope="module")
def mpc(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The zoo's mpc stack (its spec) and a copy of its pinned recorded run."""
    stack = write_member(short(by_name("mpc")), tmp_path_factory.mktemp("spec-once") / "mpc")
    log = stack.directory / "pinned.mcap"
    log.write_bytes(PINNED.read_bytes())
    return stack.spec_path, log


def test_the_log_commands_load_the_spec_once(loads, mpc, tmp_path: Path):
    spec, log = map(str, mpc)
    for argv in (("spec", "check", spec),
                 ("check", log, "--spec", spec),
                 ("generate", "--spec", spec, "--count", "2", "--seed", "1", "-o", str(tmp_path / "generated")),
                 ("extract", log, "--spec", spec, "-o", str(tmp_path / "tests"), "--module", "module",
                  "--threshold", "0", "--jobs", "1")):
        code, seen, err = loads(*argv)
        assert code == 0, (argv[0], err)
        assert seen == [spec], argv[0]
    # a run without mutations: refused once the spec is read (counted up to there)
    code, seen, err = loads("minimise", log, "--spec", spec, "-o", str(tmp_path / "minimised"))
    assert code == 2 and "no mutations" in err, err
    assert seen == [spec]


def test_policy_check_loads_the_spec_once(loads):
    code, seen, err = loads("policy", "check", str(demo_policy_path()), "--spec", str(demo_spec_path()))
    assert code == 0, err
    assert seen == [str(demo_spec_path())]


def test_the_campaign_commands_load_the_spec_once(loads, monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    def no_hunt(self: Campaign) -> CampaignResult:  # the campaign set up as fuzz sets it up, without its runs
        self.journal.set_meta(spec=str(self.config.spec_path.resolve()), seed=self.config.seed,
                              strategy=self.config.strategy, params=self.config.params, horizon=self.config.horizon,
                              cases=self.config.cases)
        return CampaignResult(cases_done=0, failures=0, buckets=0, seconds=0.0, stopped=StopReason.DONE)

    monkeypatch.setattr(Campaign, "run", no_hunt)
    camp, spec = tmp_path / "campaign", str(STEADY)
    code, seen, err = loads("fuzz", "--spec", spec, "-o", str(camp), "--cases", "1", "--no-minimise",
                            "--no-module-level")
    assert code == 0, err
    assert seen == [spec]
    for argv in (("export", str(camp), "-o", str(tmp_path / "regress"), "--spec", spec, "--check", "none"),
                 ("verify", str(camp), "--spec", spec, "--runs", "1")):
        code, seen, err = loads(*argv)
        assert code in (0, 3), (argv[0], err)  # verify: nothing to verify is "not observed"
        assert seen == [spec], argv[0]
    code, seen, err = loads("report", str(camp))  # reads the journal, not the spec
    assert code == 0, err
    assert seen == []
