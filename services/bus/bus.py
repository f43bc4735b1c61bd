"""The bus: a Zenoh session with typed publish/subscribe, health liveliness and a status queryable.

This package is the only code that imports zenoh. Keys are relative to the session's namespace.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import zenoh

from schemas.codec import DecodeError
from schemas.service import ServiceStatus, TopicCounters
from schemas.topics import Topic, topic
from services.bus.config import BusSettings, TlsError, make_zenoh_config

log = logging.getLogger("bus")

HEALTH_PREFIX = "health"
STATUS_FMT = "svc/{name}/status"


class BusError(RuntimeError):
    """The bus could not be opened or used; the message says what and where."""


@dataclass
class Counters:
    """Mutable per-topic counters; each field is written by one thread only."""

    received: int = 0
    published: int = 0
    rejected: int = 0
    last_seq: int | None = None
    last_reject_reason: str = ""

    def frozen(self) -> TopicCounters:
        return TopicCounters(
            received=self.received,
            published=self.published,
            rejected=self.rejected,
            last_seq=self.last_seq,
            last_reject_reason=self.last_reject_reason,
        )


@dataclass(frozen=True)
class RawSample:
    """A sample as it came off the wire (key relative to the namespace)."""

    key: str
    payload: bytes
    encoding: str
    attachment: bytes | None
    recv_ns: int  # wall clock at receipt (only for logs and MCAP log_time)


@dataclass
class _RejectLog:
    """Logs the first rejection per key with its reason; later ones are only counted."""

    seen: set[str] = field(default_factory=set)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def __call__(self, key: str, reason: str) -> None:
        with self.lock:
            if key in self.seen:
                return
            self.seen.add(key)
        log.warning(
            "rejected a payload on %r: %s (further rejections on it are only counted)", key, reason
        )


class Publisher:
    """Typed publisher of one topic: encodes with the topic's codec and counts."""

    def __init__(self, pub: Any, t: Topic, counters: Counters) -> None:
        self._pub, self.topic, self._c = pub, t, counters

    def put(self, msg: Any, attachment: bytes | None = None) -> None:
        self.put_bytes(self.topic.codec.encode(msg), msg.header.seq, attachment)

    def put_bytes(
        self, payload: bytes, seq: int | None = None, attachment: bytes | None = None
    ) -> None:
        """Publish an already-encoded payload (replay); ``seq`` only feeds the counters;
        ``attachment`` travels beside the payload (lock-step causal order), never in it."""
        self._pub.put(payload, attachment=attachment)
        self._c.published += 1
        self._c.last_seq = seq


class Bus:
    """One Zenoh session of one named process."""

    def __init__(self, name: str, settings: BusSettings) -> None:
        self.name, self.settings = name, settings
        self.counters: dict[str, Counters] = {}
        self.rejected_unknown = 0
        self._reject_log = _RejectLog()
        self._handles: list[Any] = []  # keep every declared entity alive
        try:
            self.session = zenoh.open(make_zenoh_config(settings, identity=name))
        except TlsError as exc:
            raise BusError(str(exc)) from None
        except zenoh.ZError as exc:
            raise BusError(_explain_open_error(settings, exc)) from None

    # ---- publish / subscribe -------------------------------------------------------------
    def counters_for(self, key: str) -> Counters:
        c = self.counters.get(key)
        if c is None:
            c = self.counters[key] = Counters()
        return c

    def publisher(self, key: str, *, express: bool = True, drop: bool = False) -> Publisher:
        """A typed publisher; ``key`` must be in the topic map. BLOCK congestion by default."""
        t = topic(key)
        cc = zenoh.CongestionControl.DROP if drop else zenoh.CongestionControl.BLOCK
        pub = self.session.declare_publisher(
            key,
            encoding=zenoh.Encoding(t.codec.zenoh_encoding),
            congestion_control=cc,
            express=express,
        )
        self._handles.append(pub)
        return Publisher(pub, t, self.counters_for(key))

    def subscribe(
        self, key: str, on_message: Callable[..., None], with_attachment: bool = False
    ) -> None:
        """Decode every sample of ``key`` with its codec; bad payloads are counted and dropped.

        ``on_message(key, msg)`` (``on_message(key, msg, attachment)`` with ``with_attachment``)
        runs on a Zenoh thread; it must be quick and must not raise.
        """
        t = topic(key)
        c = self.counters_for(key)

        def cb(sample: zenoh.Sample) -> None:
            try:
                msg = t.codec.decode(sample.payload.to_bytes())
            except DecodeError as exc:
                c.rejected += 1
                c.last_reject_reason = exc.reason
                self._reject_log(key, exc.reason)
                return
            c.received += 1
            c.last_seq = msg.header.seq
            if with_attachment:
                att = sample.attachment
                on_message(key, msg, att.to_bytes() if att is not None else None)
            else:
                on_message(key, msg)

        self._handles.append(self.session.declare_subscriber(key, _in_order(cb)))

    def subscribe_raw(self, keyexpr: str, on_sample: Callable[[RawSample], None]) -> None:
        """Every sample matching ``keyexpr``, undecoded (recorder, echo, topics)."""

        def cb(sample: zenoh.Sample) -> None:
            att = sample.attachment
            on_sample(
                RawSample(
                    key=str(sample.key_expr),
                    payload=sample.payload.to_bytes(),
                    encoding=str(sample.encoding),
                    attachment=att.to_bytes() if att is not None else None,
                    recv_ns=time.time_ns(),
                )
            )

        self._handles.append(self.session.declare_subscriber(keyexpr, _in_order(cb)))

    def reject(self, key: str, reason: str) -> None:
        """Count and log (once per key) a payload rejected above the codec (e.g. by a core)."""
        c = self.counters_for(key)
        c.rejected += 1
        c.last_reject_reason = reason
        self._reject_log(key, reason)

    def put_raw(
        self, key: str, payload: bytes, encoding: str, attachment: bytes | None = None
    ) -> None:
        """Publish bytes on any key, BLOCK congestion (replay must never drop)."""
        self.session.put(
            key,
            payload,
            encoding=zenoh.Encoding(encoding),
            congestion_control=zenoh.CongestionControl.BLOCK,
            express=True,
            attachment=attachment,
        )

    # ---- health and status ---------------------------------------------------------------
    def declare_health(self) -> None:
        """Liveliness token ``health/<name>``: present while this process's session lives."""
        self._handles.append(
            self.session.liveliness().declare_token(f"{HEALTH_PREFIX}/{self.name}")
        )

    def watch_health(self, on_change: Callable[[str, bool], None]) -> None:
        """``on_change(name, alive)`` for every service token, current ones included."""

        def cb(sample: zenoh.Sample) -> None:
            name = str(sample.key_expr).rsplit("/", 1)[-1]
            on_change(name, sample.kind == zenoh.SampleKind.PUT)

        sub = self.session.liveliness().declare_subscriber(f"{HEALTH_PREFIX}/*", cb, history=True)
        self._handles.append(sub)

    def declare_token(self, key: str) -> None:
        """A liveliness token on ``key`` (relative to the namespace), held until close."""
        self._handles.append(self.session.liveliness().declare_token(key))

    def watch_token(self, key: str, on_change: Callable[[bool], None]) -> None:
        """``on_change(present)`` whenever the liveliness token ``key`` appears or vanishes."""

        def cb(sample: zenoh.Sample) -> None:
            on_change(sample.kind == zenoh.SampleKind.PUT)

        sub = self.session.liveliness().declare_subscriber(key, cb, history=True)
        self._handles.append(sub)

    def live_services(self, timeout_s: float = 1.0) -> list[str]:
        """Names of the services whose health token is present now."""
        replies = self.session.liveliness().get(f"{HEALTH_PREFIX}/*", timeout=timeout_s)
        names = {str(r.ok.key_expr).rsplit("/", 1)[-1] for r in replies if r.ok is not None}
        return sorted(names)

    def router_connected(self) -> bool:
        """Whether this session has a link to a router now (False while one restarts)."""
        return bool(self.session.info.routers_zid())

    def discover_namespaces(self, timeout_s: float = 1.0) -> list[str]:
        """Namespaces with live services, seen from a session opened without a namespace."""
        replies = self.session.liveliness().get(f"**/{HEALTH_PREFIX}/*", timeout=timeout_s)
        out = set()
        for r in replies:
            if r.ok is not None:
                key = str(r.ok.key_expr)
                ns = key.rsplit(f"/{HEALTH_PREFIX}/", 1)[0]
                if ns != key:
                    out.add(ns)
        return sorted(out)

    def serve_status(self, get_status: Callable[[], ServiceStatus]) -> None:
        """Answer ``svc/<name>/status`` queries with the current ServiceStatus as JSON."""
        key = STATUS_FMT.format(name=self.name)

        def cb(query: zenoh.Query) -> None:
            try:
                query.reply(key, get_status().model_dump_json())
            except Exception as exc:  # a status bug must never kill the service
                log.exception("status reply failed: %s", exc)

        self._handles.append(self.session.declare_queryable(key, cb))

    def query_status(self, name: str = "*", timeout_s: float = 2.0) -> list[ServiceStatus]:
        """Statuses of the services matching ``name`` (a key chunk or ``*``)."""
        out = []
        for r in self.session.get(STATUS_FMT.format(name=name), timeout=timeout_s):
            if r.ok is None:
                continue
            try:
                out.append(ServiceStatus.model_validate_json(r.ok.payload.to_bytes()))
            except ValueError as exc:
                log.warning("unreadable status from %s: %s", r.ok.key_expr, exc)
        return sorted(out, key=lambda s: s.name)

    def close(self) -> None:
        self._handles.clear()
        if not self.session.is_closed():
            self.session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def keyexpr_intersects(pattern: str, key: str) -> bool:
    """True when the key expression ``pattern`` matches ``key`` (Zenoh semantics)."""
    return bool(zenoh.KeyExpr(pattern).intersects(zenoh.KeyExpr(key)))


def _explain_open_error(s: BusSettings, exc: Exception) -> str:
    text = str(exc)
    if s.listen and ("in use" in text.lower() or "unable to acquire lock" in text.lower()):
        return (
            f"cannot listen on {', '.join(s.listen)}: address already in use "
            f"(another run or router? choose another endpoint with --listen)"
        )
    if s.mode == "client":
        tls = (
            f"; with TLS ({s.tls_dir}), also check that the router uses the same CA and "
            f"accepts this certificate"
            if s.tls_dir
            else ""
        )
        return (
            f"cannot connect to {', '.join(s.connect)}: is the router running? "
            f"(start one with `harvest run`){tls} ({text})"
        )
    return (
        f"cannot open a Zenoh session ({s.mode}, connect={list(s.connect)}, "
        f"listen={list(s.listen)}): {text}"
    )


def _in_order(cb: Callable[[zenoh.Sample], None]) -> zenoh.handlers.Callback:
    """Run ``cb`` on the Zenoh thread that receives the link's samples, in arrival order.

    zenoh-python's default (``indirect=True``) gives every subscriber its own Python thread,
    so samples of *different* keys reach their callbacks in whatever order those threads get
    the GIL: a service with two inputs (the controller's plan/target and joint state) could
    see the joint state before the target sent before it, and a lock-step replay differed
    (measured: 1 tick in 20). Direct callbacks keep the link's order, which is the causal order
    behind one router; they must stay quick (decode and enqueue), as they already are.
    """
    return zenoh.handlers.Callback(cb, indirect=False)
