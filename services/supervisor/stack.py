"""The stack file: which services run, with which settings, restart policy and time mode.

A stack file is YAML (see deploy/stack.yaml). ``profiles`` are deep-merged over the base, so a
profile holds only what differs. Every error names the file and the field.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from services.bus import DEFAULT_ENDPOINT
from services.registry import SERVICE_MODULES, UnknownServiceError, service_def
from services.runtime.settings import (
    ServiceSettings,
    SettingsError,
    format_validation_error,
    load_settings,
    read_yaml,
)


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class RestartPolicy(_Strict):
    """What to do when a service exits or stops answering."""

    policy: Literal["never", "on-failure"] = Field(default="never", description="Restart rule.")
    max_restarts: int = Field(default=3, ge=0, description="Restarts before giving up.")
    backoff_s: float = Field(default=0.5, ge=0, description="First back-off, doubled each time.")
    backoff_max_s: float = Field(default=5.0, ge=0, description="Longest back-off, s.")


class ServiceEntry(_Strict):
    """One service of the stack."""

    settings: dict[str, Any] = Field(default_factory=dict, description="Service settings.")
    restart: RestartPolicy = Field(default_factory=RestartPolicy, description="Restart policy.")
    main: bool = Field(default=False, description="The run ends when this service exits.")
    enabled: bool = Field(default=True, description="False: listed but not started.")
    start_timeout_s: float = Field(default=60.0, gt=0, description="Until its health is up.")
    host: str | None = Field(
        default=None,
        description="Multi-host stacks: the host that runs it (None: every host). Services of "
        "other hosts are not started here but are part of the lock-step graph.",
    )


class RouterEntry(_Strict):
    """The run's router."""

    enabled: bool = Field(default=True, description="False: use an already running router.")
    listen: tuple[str, ...] = Field(default=(DEFAULT_ENDPOINT,), description="Endpoints.")
    zenoh_config: Path | None = Field(default=None, description="Zenoh json5 for the router.")
    host: str | None = Field(default=None, description="Multi-host: the host that runs it.")
    connect: tuple[str, ...] = Field(
        default=(),
        description="Where processes of this host reach the router (default: its listen "
        "endpoint on this machine); needed on hosts that do not run it.",
    )
    restart: RestartPolicy = Field(
        default_factory=RestartPolicy,
        description="Restart a router that dies (clients re-dial it, see services/bus/README).",
    )


class RecordingEntry(_Strict):
    """The run's recording."""

    enabled: bool = Field(default=True, description="Record the run to MCAP.")
    dir: Path = Field(default=Path("recordings"), description="Where the MCAP goes.")
    settings: dict[str, Any] = Field(default_factory=dict, description="Recorder settings.")
    host: str | None = Field(default=None, description="Multi-host: the host that records.")
    restart: RestartPolicy = Field(
        default_factory=lambda: RestartPolicy(policy="on-failure"),
        description="A recorder that dies restarts into the next part file (<run>.1.mcap, ...).",
    )
    required: bool = Field(
        default=False,
        description="True: the run stops when the recording fails for good (disk full, no "
        "permission). False: the robot goes on unrecorded, with a clear error in the log.",
    )


class SecurityEntry(_Strict):
    """The secured profile: mutual TLS on every link, the router's access control."""

    tls_dir: Path | None = Field(
        default=None,
        description="Certificates made by `harvest certs make DIR`; each process presents its "
        "own (common name = its name). Set: the router must listen on tls/ endpoints.",
    )


class Stack(_Strict):
    """A whole stack: the graph as data."""

    name: str = Field(description="Stack name.")
    description: str = Field(default="", description="What this stack runs.")
    mode: Literal["lockstep", "live"] = Field(default="lockstep", description="Time mode.")
    master: str | None = Field(default=None, description="The clock master (a service name).")
    scenario: str = Field(default="", description="Scenario name, recorded in the metadata.")
    seed: int | None = Field(default=None, description="Scenario seed, recorded in metadata.")
    router: RouterEntry = Field(default_factory=RouterEntry, description="The router.")
    recording: RecordingEntry = Field(default_factory=RecordingEntry, description="Recording.")
    security: SecurityEntry = Field(default_factory=SecurityEntry, description="TLS and ACL.")
    host: str | None = Field(
        default=None,
        description="Multi-host: the host this supervisor runs (`harvest run --host`); only "
        "the router, recorder and services of this host are started. None: all of them.",
    )
    services: dict[str, ServiceEntry] = Field(description="Services, in start order.")
    profiles: dict[str, dict[str, Any]] = Field(default_factory=dict, description="Overlays.")

    @model_validator(mode="after")
    def _known(self) -> Stack:
        for name in self.services:
            if name not in SERVICE_MODULES or name == "recorder":
                raise ValueError(str(UnknownServiceError(name)))
        if self.master is not None and self.master not in self.services:
            raise ValueError(f"master {self.master!r} is not one of the services")
        if self.security.tls_dir is not None:
            plain = [e for e in self.router.listen if not e.startswith(("tls/", "quic/"))]
            if plain:
                raise ValueError(
                    f"security.tls_dir is set but router.listen has unencrypted endpoints "
                    f"{plain}: use tls/HOST:PORT"
                )
        return self

    def enabled(self) -> list[str]:
        """Every enabled service of the graph, on any host."""
        return [n for n, e in self.services.items() if e.enabled]

    def here(self, host: str | None) -> bool:
        """Whether something assigned to ``host`` runs on this supervisor's host."""
        return self.host is None or host is None or host == self.host

    def local(self) -> list[str]:
        """The enabled services this supervisor starts."""
        return [n for n in self.enabled() if self.here(self.services[n].host)]

    def records_here(self) -> bool:
        return self.recording.enabled and self.here(self.recording.host)

    def routes_here(self) -> bool:
        return self.router.enabled and self.here(self.router.host)


class StackError(ValueError):
    """A stack file that cannot be used; the message names the file and the field."""


def deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = (
            deep_merge(out[k], v)
            if isinstance(v, dict) and isinstance(out.get(k), dict)
            else copy.deepcopy(v)
        )
    return out


def load_stack(
    path: Path, profile: str | None = None, overrides: dict[str, Any] | None = None
) -> Stack:
    """Read, overlay the profile and ``overrides`` (``{service: {setting: value}}``), validate."""
    try:
        raw = read_yaml(path)
    except SettingsError as exc:
        raise StackError(str(exc)) from None
    if profile:
        profiles = raw.get("profiles") or {}
        if profile not in profiles:
            raise StackError(f"{path}: no profile {profile!r} (have: {', '.join(profiles)})")
        raw = deep_merge(raw, profiles[profile])
    for svc, values in (overrides or {}).items():
        target = ("recording",) if svc == "recorder" else ("services", svc)
        node = raw
        for part in target:
            node = node.setdefault(part, {})
        node["settings"] = deep_merge(node.get("settings") or {}, values)
    try:
        return Stack.model_validate(raw)
    except ValidationError as exc:
        raise StackError(format_validation_error(exc, f"stack file {path}")) from None


def resolve_service_settings(stack: Stack) -> dict[str, ServiceSettings]:
    """Validate every enabled service's settings (and the recorder's) before anything starts;
    on every host of a multi-host stack, so the recording's metadata describes the whole run."""
    out: dict[str, ServiceSettings] = {}
    blocks = {n: stack.services[n].settings for n in stack.enabled()}
    if stack.recording.enabled:
        blocks = {"recorder": stack.recording.settings, **blocks}
    for name, block in blocks.items():
        sd = service_def(name)
        try:
            out[name] = load_settings(sd.settings, block, service=name)
        except SettingsError as exc:
            where = "recording.settings" if name == "recorder" else f"services.{name}.settings"
            raise StackError(f"{where}: {exc}") from None
    return out
