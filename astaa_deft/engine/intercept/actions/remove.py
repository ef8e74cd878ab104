"""``remove``: take fields out of the selected messages (a producer that forgot one).

    <remove>
      <field path="ego.x"/>
      <field path="points[*].id"/>
    </remove>

Each path names a struct field (its last step a name, not an index;
wildcards allowed); every place it matches loses that key. A message
without the field passes untouched for it, and the event says so. What was
removed is the event's detail, not field changes: there is no value sent to
log for a field that is not there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from lxml import etree

from astaa_deft.model.fields import FieldPath, get
from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, FIELD_PATHS_SCHEMA,
    ActionConfig, ActionDetail, ActionRuntime, MessageInfo, Pending, PinnedStep, PolicyContext, required,
)

if TYPE_CHECKING:
    from astaa_deft.model.sut import Channel
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy


@dataclass(frozen=True)
class RemoveDetail(ActionDetail):
    shown: ClassVar[tuple[str, ...]] = ("removed",)
    removed: tuple[str, ...] | None = None  # the places whose key was taken out
    skipped: str | None = None  # why nothing was removed


@ACTIONS.register_class
@dataclass(frozen=True)
class Remove(ActionConfig):
    name: ClassVar[str] = "remove"
    # Its element's type in the test case schema (spliced into testcase.xsd's Action group): the fields it acts on.
    schema: ClassVar[str] = FIELD_PATHS_SCHEMA
    detail_type: ClassVar[type[ActionDetail]] = RemoveDetail
    paths: tuple[str, ...]

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Remove:
        return cls(tuple(required(child, "path") for child in element.iterfind("field")))

    def write_xml(self, element: etree._Element) -> None:
        for path in self.paths:
            etree.SubElement(element, "field", path=path)

    def field_paths(self) -> tuple[str, ...]:
        return self.paths  # the fields it acts on (a bucket's signature names them)

    def check(self, policy: Policy, channels: tuple[Channel, ...], checker: ActionChecker) -> None:
        for text, child in zip(self.paths, checker.element.iterfind("field"), strict=True):
            path = checker.field_path(child, text, "ego.x or points[*].id")
            if path is None:
                continue
            if type(path.segments[-1]) is not str:
                checker.report(child, f"{text!r} ends in an array index: only a struct field can be removed",
                               "name a field (points[*].id); to cut an array use set with dict:array.*",
                               attribute="path")
                continue
            for channel in channels:
                checker.site(child, channel, path)

    def start(self, context: PolicyContext) -> ActionRuntime:
        return RemoveRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Remove | None:
        """The places the step removed (concrete paths); None when it removed none."""
        removed = step.detail.get("removed")
        return cls(tuple(str(path) for path in removed)) if isinstance(removed, (list, tuple)) and removed else None


class RemoveRuntime(ActionRuntime):
    def __init__(self, config: Remove, context: PolicyContext):
        self.context = context
        self.paths = tuple(FieldPath.parse(path) for path in config.paths)

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        decoded_here = item.message is None
        undecodable = item.decode(info.codec)
        if undecodable is not None:
            item.events.append(self.context.event("remove", info, item.consumers,
                                                  detail=RemoveDetail(skipped=undecodable).to_json()))
            return [item]
        removed = [str(where) for path in self.paths for where in _remove(item.message, path)]
        if not removed and decoded_here:
            item.message = None  # nothing changed: the real payload goes on
        detail = (RemoveDetail(removed=tuple(removed)) if removed
                  else RemoveDetail(skipped="no such field in this message"))
        item.events.append(self.context.event("remove", info, item.consumers, detail=detail.to_json()))
        return [item]


def _remove(message: Any, path: FieldPath) -> list[FieldPath]:
    """Delete every place ``path`` matches in ``message`` (in place); the places removed."""
    *parent, last = path.segments
    holders = get(message, FieldPath._trusted(tuple(parent))) if parent else [(FieldPath._trusted(()), message)]
    removed = []
    for where, holder in holders:
        if type(holder) is dict and last in holder:
            del holder[last]
            removed.append(FieldPath._trusted((*where.segments, last)))
    return removed
