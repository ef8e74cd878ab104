"""Liveliness tokens and queries across the star.

Publications are not the only traffic between modules: a module may wait on
another's liveliness token before it starts (e.g. a simulator that starts its
clock once the planner is up), or call another's queryable (request-reply,
which ROS 2 services and parameters use). In the star every module lives in
its own namespace, so without the proxy neither would ever meet. Both are
wired from the spec like publications (`topology.token_destinations`,
`topology.query_servers`), with a catch-all for keys no channel declares.

ROS 2 nodes on rmw_zenoh announce their graph (nodes, publishers,
subscriptions, service servers and clients) as liveliness tokens under
``@ros2_lv/...``. A chunk starting with ``@`` is verbatim in Zenoh: ``sut/**``
never matches ``sut/<module>/@ros2_lv/...``, so those tokens need a
subscriber of their own (``sut/*/@ros2_lv/**``). Their key holds the
entity's data key, and they are wired by it: a publisher's token goes where
its messages go, a subscription's to the producers it hears, a service
server's to the clients allowed to call it (and there the proxy declares a
complete queryable, since rmw_zenoh clients ask complete queryables only),
a client's to its servers, a node's to every other module. A mirrored token
keeps its key, so inside its namespace a node sees exactly the token its
peer declared, as rmw_zenoh's graph cache expects.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import zenoh

from astaa_deft.model.sut import Spec
from astaa_deft.io.ros2.tokens import ADMIN_SPACE, PUBLISHER, SERVICE, Entity, parse_token
from astaa_deft.engine.bus.topology import (
    STAR_PREFIX, module_namespace, query_servers, split_star_key, token_destinations,
)

REMOTE = zenoh.Locality.REMOTE
QUERY_TIMEOUT_S = 60.0  # the caller's own timeout governs; this only bounds a forwarded query's lifetime
QUERY_QUEUE = 1024

# `**` never matches a verbatim chunk (one starting with '@'): the ROS 2 graph needs its own expression.
ROS2_TOKENS = f"{STAR_PREFIX}/*/{ADMIN_SPACE}/**"


def ros2_hash_mismatch(spec: Spec, token: Entity) -> str | None:
    """For a publisher whose topic a channel names with another key: that key and why, in one line.

    The usual cause is a node built from another definition of the type (a
    different RIHS01 hash): its messages then go on a key no channel
    declares. Reported as that undeclared key, with the channel it missed.
    """
    key = token.data_key
    if token.kind != PUBLISHER or key is None or any(ch.key == key for ch in spec.channels):
        return None
    observed = key.split("/")  # domain, topic chunks…, dds type, hash
    for ch in spec.channels:
        declared = ch.key.split("/")
        if len(declared) >= 4 and declared[0] == observed[0] and declared[1:-2] == observed[1:-2]:
            what = "type hash" if declared[-2] == observed[-2] else "type"
            return (f"{key} (the node's {what} differs from channel '{ch.name}''s key {ch.key}: "
                    f"another definition of the message? give the channel this key, or fix the definition)")
    return None


def ros2_token_destinations(spec: Spec, module: str, token: Entity) -> tuple[str, ...]:
    """Modules that see ``module``'s ROS 2 token: wired by the data key its entity puts or serves.

    A publisher's or a service server's token goes where its channel goes
    (``token_destinations``: to the consumers, or everywhere for a key no
    channel declares); a subscription's or a client's goes to the modules it
    hears or calls (``query_servers``, the inverse wiring). A node's token
    reaches every other module: a node's existence carries no data, and
    ``ros2 node list`` inside any module lists them all.
    """
    key = token.data_key
    if key is None:
        return tuple(m.name for m in spec.modules if m.name != module)
    if token.kind in (PUBLISHER, SERVICE):
        return token_destinations(spec, module, key)
    return query_servers(spec, module, key)


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
        self._subscribers: list[zenoh.Subscriber] = []
        self.services = StarServices(session)
        self._reported: set[str] = set()
        self.mirrored = 0

    def start(self) -> None:
        # history=True: tokens declared before the proxy came up are mirrored as well.
        self._subscribers = [self.session.liveliness().declare_subscriber(expr, self._on_token, history=True)
                             for expr in (f"{STAR_PREFIX}/**", ROS2_TOKENS)]

    def stop(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()
        self._subscribers = []
        self.services.stop()
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
                self.services.withdraw(full_key)
                return
            parts = split_star_key(full_key)
            if parts is None or full_key in self._mirrors:
                return
            module, key = parts
            ros2 = parse_token(key) if key.startswith(ADMIN_SPACE + "/") else None
            if key.startswith(ADMIN_SPACE + "/") and ros2 is None:
                return  # not an rmw_zenoh entity: no wiring to follow
            destinations = (ros2_token_destinations(self.spec, module, ros2) if ros2 is not None
                            else token_destinations(self.spec, module, key))
            if ros2 is not None and ros2.kind == SERVICE and ros2.data_key is not None:
                self.services.offer(full_key, module, ros2.data_key, destinations)
            tokens = []
            for consumer in destinations:
                mirror_key = f"{module_namespace(consumer)}/{key}"
                self._mirror_keys.add(mirror_key)
                tokens.append(self.session.liveliness().declare_token(mirror_key))
            self._mirrors[full_key] = tokens
            self.mirrored += 1
        if ros2 is not None:
            mismatch = ros2_hash_mismatch(self.spec, ros2)
            if mismatch and mismatch not in self._reported:
                self._reported.add(mismatch)
                self.on_undeclared(module, mismatch)
            return  # otherwise graph, not data: an undeclared topic is reported when its messages flow
        if not any(ch.key == key for ch in self.spec.channels) and \
                not any(t.key == key and t.producer == module for t in self.spec.liveliness):
            self.on_undeclared(module, f"liveliness:{key}")  # declare it under 'liveliness:' (docs/spec.md)


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
        forward_query(self.session, query, caller, key, servers=servers)


def forward_query(session: zenoh.Session, query: zenoh.Query, caller: str, key: str, *,
                  servers: tuple[str, ...]) -> None:
    """Ask each server's namespace what ``caller`` asked on ``key`` and relay every reply into the caller's.

    Payload, encoding and attachment go as they came (a ROS 2 request's
    attachment carries the sequence number and GID its reply must echo).
    """
    caller_ns = module_namespace(caller)
    params = str(query.parameters)
    for server in servers:
        selector = f"{module_namespace(server)}/{key}" + (f"?{params}" if params else "")
        payload = query.payload
        replies = session.get(
            selector, payload=payload, encoding=query.encoding if payload is not None else None,
            attachment=query.attachment, timeout=QUERY_TIMEOUT_S, allowed_destination=REMOTE)
        for reply in replies:
            try:
                _relay(query, reply, caller_ns)
            except zenoh.ZError:
                return  # the caller gave up (its timeout passed): nobody to answer


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


class StarServices:
    """A ROS 2 service server's queryable, mirrored into the namespace of each client wired to call it.

    rmw_zenoh's clients (and zenoh-ros2-sdk's) query with target
    ALL_COMPLETE: only queryables declared complete are asked, which the
    star's catch-all (``sut/**``, complete=False: it cannot answer for all of
    it) is not. So for each service server token seen, the proxy declares a
    complete queryable on exactly the service key in each wired client's
    namespace, and forwards what arrives there to the server(s).
    """

    def __init__(self, session: zenoh.Session):
        self.session = session
        self._lock = threading.Lock()
        self._servers: dict[tuple[str, str], dict[str, str]] = {}  # (client, key) → {token: server module}
        self._queryables: dict[tuple[str, str], zenoh.Queryable] = {}
        self._offers: dict[str, list[tuple[str, str]]] = {}  # server token → the (client, key) it serves
        self.forwarded = 0

    def offer(self, token: str, server: str, key: str, clients: tuple[str, ...]) -> None:
        with self._lock:
            for client in clients:
                slot = (client, key)
                self._servers.setdefault(slot, {})[token] = server
                self._offers.setdefault(token, []).append(slot)
                if slot not in self._queryables:
                    self._queryables[slot] = self.session.declare_queryable(
                        f"{module_namespace(client)}/{key}", self._handler(slot), complete=True, allowed_origin=REMOTE)

    def withdraw(self, token: str) -> None:
        with self._lock:
            for slot in self._offers.pop(token, []):
                servers = self._servers.get(slot, {})
                servers.pop(token, None)
                if not servers:
                    self._servers.pop(slot, None)
                    queryable = self._queryables.pop(slot, None)
                    if queryable is not None:
                        queryable.undeclare()

    def stop(self) -> None:
        with self._lock:
            for queryable in self._queryables.values():
                queryable.undeclare()
            self._queryables.clear()
            self._servers.clear()
            self._offers.clear()

    def _handler(self, slot: tuple[str, str]) -> Callable[[zenoh.Query], None]:
        return lambda query: self._on_query(query, slot)

    def _on_query(self, query: zenoh.Query, slot: tuple[str, str]) -> None:
        with self._lock:
            servers = tuple(dict.fromkeys(self._servers.get(slot, {}).values()))
        self.forwarded += 1
        # A thread per call, as for the catch-all: a slow service must not hold up Zenoh's callback thread.
        threading.Thread(target=self._serve, args=(query, slot, servers), name="star-service", daemon=True).start()

    def _serve(self, query: zenoh.Query, slot: tuple[str, str], servers: tuple[str, ...]) -> None:
        try:
            forward_query(self.session, query, slot[0], slot[1], servers=servers)
        finally:
            query.drop()
