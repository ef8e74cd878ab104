"""Concurrency that follows the machine: more runs at once when the other load falls (pure decision;
the live behaviour with a real CPU-load process: benchmarks/bench_campaign_rise.py)."""

from __future__ import annotations

from astaa_deft.orchestration.campaign.calibration import MachineNow, RunShare, raised, workers_for

SHARE = RunShare(cores=0.3, rss_mb=300.0, runs=1)  # the demo: ~0.3 core a run


def test_while_other_work_holds_the_cores_no_more_runs_go_at_once():
    # Two busy processes of other work on two cores, one run of ours in flight.
    decision = raised(SHARE, MachineNow(cores=2, memory_mb=8000.0, load1=2.3, ours=0.3), most=8, workers=1,
                      ceiling=None)
    assert decision.workers == 1 and abs(decision.other_load - 2.0) < 1e-9


def test_when_the_other_load_falls_one_more_run_goes_at_once_a_step_at_a_time():
    decision = raised(SHARE, MachineNow(cores=2, memory_mb=8000.0, load1=0.4, ours=0.3), most=8, workers=1,
                      ceiling=None)
    assert decision.workers == 2  # five would fit: one step, the twins' timing judges the next
    assert workers_for(SHARE, 2, 8000.0, most=8, other_load=0.1) == 4
    assert "other load fell to 0.1" in decision.why


def test_never_up_to_a_count_whose_timing_drifted():
    assert raised(SHARE, MachineNow(cores=2, memory_mb=8000.0, load1=0.4, ours=0.6), most=8, workers=2,
                  ceiling=3).workers == 2
    assert raised(SHARE, MachineNow(cores=2, memory_mb=8000.0, load1=0.4, ours=0.6), most=8, workers=2,
                  ceiling=4).workers == 3


def test_memory_bounds_the_rise_too():
    assert raised(RunShare(0.3, 3000.0, 1), MachineNow(cores=2, memory_mb=8000.0, load1=0.3, ours=0.3), most=8,
                  workers=1, ceiling=None).workers == 1  # 8 GB × 0.5 holds one 3 GB run
