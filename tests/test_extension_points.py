"""Each extension point takes one new file: a throwaway action, monitor kind, strategy and codec, each one module
of a temporary package that registers itself, used through the public path (the test case reader and its schema,
the spec reader, the monitor set, the engine, the command line's choices, the campaign's strategy table)."""

from __future__ import annotations

import importlib
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.cli.program import build_parser
from astaa_deft.engine.intercept import Interceptor, load_dictionary, parse_testcase
from astaa_deft.engine.intercept.actions import ACTIONS
from astaa_deft.engine.monitor.kinds import KINDS
from astaa_deft.engine.monitor.monitorset import MonitorSet
from astaa_deft.engine.spec.loader import load_spec_text
from astaa_deft.io.codecs import CODECS, get_codec
from astaa_deft.model.errors import InputError
from astaa_deft.orchestration.campaign.strategies import STRATEGIES

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "throwaway_extensions"

# One file per extension, as a developer would write it (each registers itself at import).
FILES = {
    "stamp_action.py": '''
        """A throwaway action: forwards the message unchanged and logs that it saw it."""
        from dataclasses import dataclass
        from typing import ClassVar

        from astaa_deft.engine.intercept.actions.base import ACTIONS, ActionConfig, ActionRuntime


        @ACTIONS.register_class
        @dataclass(frozen=True)
        class Stamp(ActionConfig):
            name: ClassVar[str] = "stamp"
            schema: ClassVar[str] = ('<xs:complexType><xs:attribute name="note" type="Name" use="required"/>'
                                     '</xs:complexType>')
            note: str = ""

            @classmethod
            def from_xml(cls, element, checker):
                return cls(element.get("note"))

            def write_xml(self, element):
                element.set("note", self.note)

            def start(self, context):
                return StampRuntime(context)


        class StampRuntime(ActionRuntime):
            def __init__(self, context):
                self.context = context

            def apply(self, item, info):
                item.events.append(self.context.event("stamp", info, item.consumers))
                return [item]
    ''',
    "silence_kind.py": '''
        """A throwaway monitor kind: at most `max_messages` messages on a channel."""
        from dataclasses import dataclass
        from typing import ClassVar

        from astaa_deft.engine.monitor.base import NO_VIOLATIONS, Invariant, Monitor, ReplayJudges
        from astaa_deft.engine.monitor.kinds import Kind

        KEYS = ("channel", "max_messages")
        REQUIRED = ("channel",)


        @dataclass(frozen=True, kw_only=True)
        class SilenceInvariant(Invariant):
            kind: ClassVar[str] = "silence"
            replay_judges: ClassVar[ReplayJudges] = ReplayJudges.TIMING  # a module's lateness, as a deadline's
            crash_kind: ClassVar[bool] = True  # (a throwaway kind claiming the trait, to see it read)
            channel: str
            max_messages: int = 0

            def margin_source(self):
                return (self.channel, "text")

            def margin_of(self, value):
                return 0.5 if isinstance(value, str) else None


        def parse(reader, node, common):
            channel = reader.channel(node.value.get("channel"))
            return None if channel is None else SilenceInvariant(channel=channel.name, **common)


        class SilenceMonitor(Monitor):
            def channels(self):
                return {self.invariant.channel}

            def on_message(self, channel, time_ns, value, seq):
                self.evaluations += 1
                return [self.violation(time_ns, "a message", channel=channel, seq=seq)] if seq > 0 else NO_VIOLATIONS


        def monitor(invariant, context):
            return SilenceMonitor(invariant, context)


        Kind.register(SilenceInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
    ''',
    "upper_codec.py": '''
        """A throwaway codec: a message is the text of one field, upper case."""
        from astaa_deft.io.codecs.base import CODECS, Codec, DecodeError


        class UpperCodec(Codec):
            name = "upper"

            def decode(self, payload):
                try:
                    return {"text": payload.decode("ascii")}
                except UnicodeDecodeError as exc:
                    raise DecodeError(str(exc)) from None

            def encode(self, value):
                return value["text"].upper().encode("ascii")

            def carries(self, value):
                return None


        CODECS.register(UpperCodec.name, UpperCodec())
    ''',
    "idle_strategy.py": '''
        """A throwaway strategy: every case the same empty-handed delay."""
        from astaa_deft.engine.intercept.actions.delay import Delay
        from astaa_deft.engine.intercept.testcase import Policy, TestCase
        from astaa_deft.orchestration.campaign.strategies.base import STRATEGIES, Proposal, Strategy


        @STRATEGIES.register_class
        class IdleStrategy(Strategy):
            name = "idle"

            def __init__(self, spec, dictionary, seed, duration):
                self.channel = spec.channels[0].name

            def propose(self, number):
                policy = Policy(id="p", action=Delay(1.0), channels=(self.channel,))
                return Proposal(TestCase(id=f"tc-{number:06d}", seed=0, description="idle", policies=(policy,)))
    ''',
}

SPEC = """
name: throwaway
modules:
  - {name: talker, command: [python, -c, "pass"]}
  - {name: listener, command: [python, -c, "pass"]}
channels:
  - {name: data, key: test/data, producer: talker, consumers: [listener], type: Note, encoding: %(encoding)s}
types:
  Note:
    text: string
invariants:
  - {name: quiet, kind: %(kind)s, channel: data}
"""


@pytest.fixture
def extensions(tmp_path):
    """The temporary package, imported (each module registers itself); unregistered and forgotten afterwards."""
    root = tmp_path
    package = root / PACKAGE
    package.mkdir()
    (package / "__init__.py").write_text("")
    for name, text in FILES.items():
        (package / name).write_text(textwrap.dedent(text))
    sys.path.insert(0, str(root))
    try:
        for name in FILES:
            importlib.import_module(f"{PACKAGE}.{name.removesuffix('.py')}")
        yield
    finally:
        ACTIONS.unregister("stamp")
        KINDS.unregister("silence")
        CODECS.unregister("upper")
        STRATEGIES.unregister("idle")
        sys.path.remove(str(root))
        for module in [m for m in sys.modules if m == PACKAGE or m.startswith(PACKAGE + ".")]:
            del sys.modules[module]


def test_a_spec_reads_the_new_codec_and_monitor_kind_and_the_monitor_set_runs_it(extensions):
    spec = load_spec_text(SPEC % {"encoding": "upper", "kind": "silence"}, "throwaway.yaml")
    assert spec.channel("data").encoding == "upper" and [i.kind for i in spec.invariants] == ["silence"]
    codec = get_codec("upper")
    assert codec.decode(codec.encode({"text": "hi"})) == {"text": "HI"}
    monitors = MonitorSet(spec, 0)
    assert [v.invariant for v in monitors.on_message("data", 5, {"text": "HI"}, 1)] == ["quiet"]


def test_what_a_new_kind_may_be_judged_by_is_its_traits_not_its_name(extensions):
    from astaa_deft.analysis.minimise.replay_model import replay_entry_for
    from astaa_deft.engine.monitor.verdict import run_verdict
    from astaa_deft.model.records import ProcessExit, Verdict, Violation
    from astaa_deft.orchestration.campaign.module_tests import is_crash_bucket
    from astaa_deft.orchestration.campaign.runner import MarginWatch

    spec = load_spec_text(SPEC % {"encoding": "json", "kind": "silence"}, "throwaway.yaml")
    # A timing invariant: a replay of one module's outputs does not judge it (the spec here replays nothing).
    assert replay_entry_for(spec, "quiet")[0] is None
    # A timing violation after its module's crash is the crash's consequence: only the exit counts.
    late = Violation(invariant="quiet", invariant_kind="silence", severity="high", time_ns=2_000, channel="data",
                     seq=None, message=None, detail="late", crash=Verdict.RESTART, module="talker")
    crashed = ProcessExit(module="talker", pid=1, returncode=1, signal=None, time_ns=1_000, during_shutdown=False)
    assert run_verdict([late], [crashed], ["talker", "listener"]).klass is Verdict.ABORT
    assert is_crash_bucket("Silent", "quiet", spec)  # its crash_kind trait
    # Its margin hook: the campaign's margin watch measures it on its channel and field.
    watch = MarginWatch(spec)
    assert [(inv.name, source) for inv, source in watch.watched] == [("quiet", ("data", "text"))]


def test_the_spec_reader_lists_what_is_registered(extensions):
    with pytest.raises(InputError) as caught:
        load_spec_text(SPEC % {"encoding": "lower", "kind": "silense"}, "throwaway.yaml")
    text = str(caught.value)
    assert "unknown encoding 'lower'" in text and "upper" in text  # the registered codecs are the choices
    assert "did you mean 'silence'" in text or "silence" in text


def test_a_test_case_with_the_new_action_is_read_checked_and_run(extensions):
    spec = load_spec_text(SPEC % {"encoding": "json", "kind": "silence"}, "throwaway.yaml")
    xml = b'<testcase id="tc" seed="1"><description/><policy id="p"><channel>data</channel>' \
          b'<stamp note="seen"/></policy></testcase>'
    testcase = parse_testcase(xml, "tc.xml", spec)
    assert type(testcase.policies[0].action).__name__ == "Stamp" and testcase.policies[0].action.note == "seen"
    assert parse_testcase(testcase.to_xml(), "again.xml", spec) == testcase  # written back by its own module
    with pytest.raises(InputError, match="note"):  # its schema fragment is in force: the attribute is required
        parse_testcase(xml.replace(b' note="seen"', b""), "tc.xml", spec)
    interceptor = Interceptor(testcase, spec, load_dictionary())
    payload = get_codec("json").encode({"text": "x"})
    [delivery] = interceptor.on_message("data", ("listener",), payload, 0.5)
    assert delivery.event is not None and delivery.event.action == "stamp" and delivery.consumers == ("listener",)


def test_the_command_line_and_the_campaign_offer_the_new_strategy(extensions, capsys):
    parser = build_parser()
    assert parser.parse_args(["fuzz", "-o", "out", "--strategy", "idle"]).strategy == "idle"
    with pytest.raises(SystemExit):
        parser.parse_args(["fuzz", "-o", "out", "--strategy", "idel"])
    assert "'idle'" in capsys.readouterr().err  # the choices listed are the registry's
    spec = load_spec_text(SPEC % {"encoding": "json", "kind": "silence"}, "throwaway.yaml")
    proposal = STRATEGIES["idle"](spec, load_dictionary(), 1, 10.0).propose(3)
    assert parse_testcase(proposal.testcase.to_xml(), "p.xml", spec).id == "tc-000003"


def test_without_the_package_none_of_them_exists():
    for registry, name in ((ACTIONS, "stamp"), (KINDS, "silence"), (CODECS, "upper"), (STRATEGIES, "idle")):
        assert name not in registry
