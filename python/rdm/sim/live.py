"""Live telemetry: a Foxglove WebSocket server (the ``foxglove-sdk`` package, module
``foxglove``) carrying the channels of the run's ``signals.mcap`` while the run goes on
(``rdm sim --live``, ``rdm onboard --live``; docs/sim.md "Live telemetry").

Each channel has the topic, schema name, schema (``jsonschema``, inferred from the first
message as :class:`rdm.sim.mcap_log.McapLogger` infers it) and message encoding (``json``) of
the MCAP channel, and each message the text the MCAP holds (compact ``json.dumps``, NaN and
infinities as null) at the same log time (the run's time in ns), so one Foxglove layout serves
the live view and the file.

The publisher never waits: a message is encoded only while a client is subscribed to its
channel (``Channel.has_sinks``), and ``Channel.log`` hands it to the server's own threads,
which drop the oldest message of a client whose queue is full
(``message_backlog_size``). A client that disconnects ends its subscriptions and nothing else.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from importlib import resources
from pathlib import Path
from typing import Any

#: ASSUMPTION: the defaults of ``--live-host`` and ``--live-port``: the loopback interface
#: (nothing is reachable from another computer unless asked for) and Foxglove's own default
#: port, which Foxglove Studio's "Open connection" dialog proposes.
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
#: Messages queued per client before the oldest is dropped (the SDK's default is 1024).
BACKLOG = 1024


class LiveError(RuntimeError):
    """The server could not start (the port is taken, the host cannot be bound)."""


def layout_path() -> Path:
    """The Foxglove layout file shipped in the package (``rdm/data/foxglove/rdm_layout.json``):
    attitude, position, rotor duties, foot-sensor force and the perching state."""
    return Path(str(resources.files("rdm") / "data" / "foxglove" / "rdm_layout.json"))


class LivePublisher:
    """A Foxglove WebSocket server on ``host``:``port`` (0: any free port, see :attr:`port`)
    with its own ``foxglove.Context``; :meth:`log_json` publishes a record on a topic.
    :meth:`close` stops the server (idempotent). Used from one thread."""

    def __init__(
        self,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        name: str = "rdm",
        advertise: Mapping[str, Mapping[str, Any]] | None = None,
    ):
        """``advertise``: topic -> an example record of channels made before the server
        starts (a client then finds them in its first advertisement; a channel made while a
        client connects may be missed by foxglove-sdk 0.30's server: it answers the client's
        subscription with "unknown channel")."""
        import foxglove

        from rdm.sim.mcap_log import _jsonable, _schema_of

        self._foxglove = foxglove
        self._jsonable, self._schema_of = _jsonable, _schema_of
        self._context = foxglove.Context()
        self._channels: dict[str, Any] = {}
        for topic, example in (advertise or {}).items():
            self._channel(topic, self._jsonable(dict(example)), "")
        try:
            self._server = foxglove.start_server(
                name=name,
                host=host,
                port=port,
                context=self._context,
                message_backlog_size=BACKLOG,
            )
        except Exception as exc:  # the SDK raises its own error type (a RuntimeError)
            raise LiveError(f"--live-port {port} on {host}: {exc}") from None
        self.host = host
        self.port: int = int(self._server.port)
        self._closed = False
        #: messages handed to the server (while a client was subscribed)
        self.published = 0

    def _channel(self, topic: str, doc: dict[str, Any], schema_name: str) -> Any:
        schema = self._schema_of(doc)
        name = schema_name or topic.strip("/").replace("/", ".") or "root"
        ch = self._foxglove.Channel(
            topic,
            schema=self._foxglove.Schema(
                name=name,
                encoding="jsonschema",
                data=json.dumps(schema, sort_keys=True).encode(),
            ),
            message_encoding="json",
            context=self._context,
        )
        self._channels[topic] = ch
        return ch

    def wants(self, topic: str) -> bool:
        """Whether a record on ``topic`` would be sent: its channel is not advertised yet,
        or a client is subscribed to it."""
        ch = self._channels.get(topic)
        return not self._closed and (ch is None or ch.has_sinks())

    def log_json(
        self, topic: str, t: float, values: Mapping[str, Any], schema_name: str = ""
    ) -> None:
        """Publish ``values`` on ``topic`` at time ``t`` [s] as the MCAP's JSON record (the
        channel advertised at its first record); nothing is encoded while no client is
        subscribed to the topic."""
        if self._closed:
            return
        ch = self._channels.get(topic)
        if ch is not None and not ch.has_sinks():
            return
        doc = self._jsonable(dict(values))
        if ch is None:
            ch = self._channel(topic, doc, schema_name)
            if not ch.has_sinks():
                return
        ns = round(t * 1e9) if math.isfinite(t) and t >= 0 else 0
        ch.log(json.dumps(doc, separators=(",", ":")).encode(), log_time=ns)
        self.published += 1

    def log_truth(self, truth: Any, topic: str = "/plant/ground_truth") -> None:
        """Publish a :class:`rdm.plant.GroundTruth` (every field) at its own time."""
        ch = self._channels.get(topic)
        if ch is not None and not ch.has_sinks():
            return
        fields = truth.__dataclass_fields__
        self.log_json(topic, float(truth.time), {k: getattr(truth, k) for k in fields})

    def close(self) -> None:
        """Stop the server; clients see the connection close."""
        if self._closed:
            return
        self._closed = True
        self._server.stop()


class LiveTee:
    """A signal logger (``log_json``, ``log_truth``, ``finish``) that hands every call to an
    :class:`rdm.sim.mcap_log.McapLogger` (or None: no file) and to a :class:`LivePublisher`;
    the file gets the same calls as without the publisher. A publisher's failure is counted
    (:attr:`live_errors`) and turns the publisher off, never reaching the run."""

    def __init__(self, logger: Any, live: LivePublisher) -> None:
        self.logger, self.live = logger, live
        self.live_errors = 0

    def _publish(self, method: str, *args: Any) -> None:
        if self.live is None:
            return
        try:
            getattr(self.live, method)(*args)
        except Exception:
            self.live_errors += 1
            self.live = None  # type: ignore[assignment]

    def log_json(self, topic: str, t: float, values: Mapping[str, Any]) -> None:
        if self.logger is not None:
            self.logger.log_json(topic, t, values)
        self._publish("log_json", topic, t, values)

    def log_truth(self, truth: Any, topic: str = "/plant/ground_truth") -> None:
        if self.logger is not None:
            self.logger.log_truth(truth, topic)
        self._publish("log_truth", truth, topic)

    def finish(self) -> None:
        if self.logger is not None:
            self.logger.finish()


_LIVE: ContextVar[LivePublisher | None] = ContextVar("rdm_sim_live", default=None)


def live_publisher() -> LivePublisher | None:
    """The publisher of the enclosing :func:`live_to` block, else None."""
    return _LIVE.get()


@contextmanager
def live_to(publisher: LivePublisher) -> Iterator[None]:
    """Every stack built inside the block also publishes its signal log on ``publisher``."""
    token = _LIVE.set(publisher)
    try:
        yield
    finally:
        _LIVE.reset(token)
