"""The semantic zoo (tests/sut/semantic_zoo.yaml) driven without processes: its source's states through a
real ``Interceptor`` into its consumer's checks, and which seeded defect (if any) a test case reaches."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

from astaa_deft.io.codecs import get_codec
from astaa_deft.engine.intercept import Interceptor, TestCase, load_dictionary
from astaa_deft.engine.spec.loader import load_spec

SUT_DIR = Path(__file__).parent / "sut"
ZOO_SPEC_PATH = SUT_DIR / "semantic_zoo.yaml"
ZOO_SPEC = load_spec(ZOO_SPEC_PATH)
DICTIONARY = load_dictionary()
SEMANTIC = ("boundary", "angle", "units", "arrays", "type", "siblings", "stale")
_JSON = get_codec("json")


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"zoo_{name}", SUT_DIR / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SOURCE, CONSUMER = _load("zoo_source"), _load("zoo_consumer")


def defect_of(exc: Exception) -> str:
    """The family whose seeded defect raised ``exc`` (zoo_consumer.py's docstring)."""
    if isinstance(exc, IndexError):
        return "boundary"
    if isinstance(exc, ZeroDivisionError):
        return "stale"
    if isinstance(exc, (KeyError, TypeError)):
        return "type"
    return str(exc).split(" defect")[0]


def reached(testcase: TestCase, defects: bool, messages: int = 60) -> str | None:
    """The defect ``testcase`` reaches over ``messages`` states at 20 Hz (None: none)."""
    interceptor = Interceptor(testcase, ZOO_SPEC, DICTIONARY)
    consumer = CONSUMER.Consumer(defects)
    try:
        for i in range(1, messages + 1):
            now = i * SOURCE.PERIOD
            deliveries = interceptor.on_message("state", ("consumer",), _JSON.encode(SOURCE.state(i)), now)
            deliveries += interceptor.on_tick(now)
            for delivery in sorted(deliveries, key=lambda d: d.at) + (
                    interceptor.flush(now) if i == messages else []):
                if delivery.consumers:
                    consumer.handle(_JSON.decode(delivery.payload))
    except Exception as exc:  # a seeded defect (the same code raises in the live consumer)
        return defect_of(exc)
    return None
