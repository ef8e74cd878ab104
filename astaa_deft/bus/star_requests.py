"""Liveliness tokens and queries across the star.

Publications are not the only traffic between modules: a module may wait on
another's liveliness token before it starts (e.g. a simulator that starts its
clock once the planner is up), or call another's queryable (request-reply,
which ROS 2 services and parameters use). In the star every module lives in
its own namespace, so without the proxy neither would ever meet. Both are
wired from the spec like publications (`topology.token_destinations`,
`topology.query_servers`), with a catch-all for keys no channel declares.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import zenoh

from ..spec.model import Spec
from .topology import STAR_PREFIX, module_namespace, query_servers, split_star_key, token_destinations

REMOTE = zenoh.Locality.REMOTE
QUERY_TIMEOUT_S = 60.0  # the caller's own timeout governs; this only bounds a forwarded query's lifetime
QUERY_QUEUE = 1024


class StarLiveliness:
    """Mirror each module's liveliness tokens into the namespaces of the modules wired to see them."""

    def __init__(self, session: zenoh.Session, spec: Spec,
                 on_undeclared: Callable[[str, str], None] = lambda module, key: None):
        self.session = session
        self.spec = spec
        self.on_undeclared = on_undeclared
        self._lock = threading.Lock()
        self._mirrors: dict[str, list[zenoh.LivelinessToken]] = {}  # source full key → mirrored tokens
        self._mirror_keys: set[str] = set()  # our own tokens, which our subscriber sees too
        self._subscriber: zenoh.Subscriber | None = None
        self.mirrored = 0

    def start(self) -> None:
        # history=True: tokens declared before the proxy came up are mirrored as well.
        self._subscriber = self.session.liveliness().declare_subscriber(
            f"{STAR_PREFIX}/**", self._on_token, history=True)

    def stop(self) -> None:
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None
        with self._lock:
            for tokens in self._mirrors.values():
                for token in tokens:
                    token.undeclare()
            self._mirrors.clear()
            self._mirror_keys.clear()

    def _on_token(self, sample: zenoh.Sample) -> None:
        full_key = str(sample.key_expr)
        with self._lock:
            if full_key in self._mirror_keys:
                return
            if sample.kind == zenoh.SampleKind.DELETE:
                for token in self._mirrors.pop(full_key, []):
                    token.undeclare()
                return
            parts = split_star_key(full_key)
            if parts is None or full_key in self._mirrors:
                return
            module, key = parts
            destinations = token_destinations(self.spec, module, key)
            tokens = []
            for consumer in destinations:
                mirror_key = f"{module_namespace(consumer)}/{key}"
                self._mirror_keys.add(mirror_key)
                tokens.append(self.session.liveliness().declare_token(mirror_key))
            self._mirrors[full_key] = tokens
            self.mirrored += 1
        if not any(ch.key == key for ch in self.spec.channels):
            self.on_undeclared(module, f"liveliness:{key}")


class StarQueries:
    """Answer each module's queries by asking the modules wired to serve them.

    One queryable on the whole star (remote origin only, so the proxy never
    answers the queries it forwards itself); each query is served on a thread
    of its own, because a service may take as long as it likes and must not
    hold up the others.
    """

    def __init__(self, session: zenoh.Session, spec: Spec,
                 on_undeclared: Callable[[str, str], None] = lambda module, key: None):
        self.session = session
        self.spec = spec
        self.on_undeclared = on_undeclared
        self._queryable: zenoh.Queryable | None = None
        self._thread: threading.Thread | None = None
        self._undeclared_seen: set[str] = set()
        self.forwarded = 0

    def start(self) -> None:
        self._queryable = self.session.declare_queryable(
            f"{STAR_PREFIX}/**", zenoh.handlers.FifoChannel(QUERY_QUEUE), complete=False, allowed_origin=REMOTE)
        self._thread = threading.Thread(target=self._pump, name="star-queries", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        if self._queryable is not None:
            self._queryable.undeclare()
            self._queryable = None
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _pump(self) -> None:
        queryable = self._queryable
        if queryable is None:  # stopped before the pump began
            return
        try:
            for query in queryable:  # ends when the queryable is undeclared
                threading.Thread(target=self._serve, args=(query,), name="star-query", daemon=True).start()
                del query  # the serving thread alone decides when the query is finished
        except zenoh.ZError:
            pass

    def _serve(self, query: zenoh.Query) -> None:
        try:
            self._answer(query)
        finally:
            query.drop()  # the final reply: the caller's get() ends here, not at its timeout

    def _answer(self, query: zenoh.Query) -> None:
        full_key = str(query.key_expr)
        parts = split_star_key(full_key)
        if parts is None:
            return
        caller, key = parts
        servers = query_servers(self.spec, caller, key)
        if not any(ch.key == key for ch in self.spec.channels) and key not in self._undeclared_seen:
            self._undeclared_seen.add(key)
            self.on_undeclared(caller, f"query:{key}")
        self.forwarded += 1
        caller_ns = module_namespace(caller)
        params = str(query.parameters)
        for server in servers:
            selector = f"{module_namespace(server)}/{key}" + (f"?{params}" if params else "")
            payload = query.payload
            replies = self.session.get(
                selector, payload=payload, encoding=query.encoding if payload is not None else None,
                attachment=query.attachment, timeout=QUERY_TIMEOUT_S, allowed_destination=REMOTE)
            for reply in replies:
                try:
                    self._relay(query, reply, caller_ns)
                except zenoh.ZError:
                    return  # the caller gave up (its timeout passed): nobody to answer

    @staticmethod
    def _relay(query: zenoh.Query, reply: zenoh.Reply, caller_ns: str) -> None:
        if reply.ok is not None:
            sample = reply.ok
            parts = split_star_key(str(sample.key_expr))
            if parts is None:
                return
            key = f"{caller_ns}/{parts[1]}"
            if sample.kind == zenoh.SampleKind.DELETE:
                query.reply_del(key, attachment=sample.attachment, timestamp=sample.timestamp)
            else:
                query.reply(key, sample.payload, encoding=sample.encoding,
                            attachment=sample.attachment, timestamp=sample.timestamp)
        elif reply.err is not None:
            query.reply_err(reply.err.payload, encoding=reply.err.encoding)
