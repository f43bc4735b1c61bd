"""`harvest bench harvest`: the whole harvest on a scenario over seeds, for each order policy.

Two ways to run a seed:

* ``inproc`` (default): every core (sim, detector, tracker, scene, controller, planner) in one
  process, in lock-step order (services.runtime.inproc): the same messages as the stack without
  process start-up and the bus, so many seeds fit in the time;
* ``stack``: the real stack under the supervisor (one process per service, Zenoh, recorded),
  evaluated from the recording.

Evaluation uses the sim's ground truth (allowed here: it is the judge, never an input of the
planner): a fruit is *reachable* when the IK reaches its harvest pose and pre-pose computed from
its true centre and semi-axes (the planner's own reachability test on perfect data); the
planner's fruit (track IDs) are matched to sim fruit by where the track was at the time (a
tracker re-uses a harvested fruit's ID for another fruit: the ID alone is ambiguous). In clutter a
fruit also needs an order in which every neighbour in its tools' way goes first (the planner's
own clearance check, on the true fruit).
"""

from __future__ import annotations

import bisect
import statistics
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from schemas.harvest import RunSummary
from schemas.scene import SceneState
from schemas.sim import GroundTruth
from services.planner.bench_rows import (
    DIRTY,
    RowsError,
    append_row,
    code_version,
    combined,
    read_rows,
    reusable,
    run_key,
)

CHAIN = ("detector", "tracker", "scene")
SETTABLE = ("sim", *CHAIN, "controller", "planner")  # services a run's --set may reach
MATCH_M = 0.06  # a track's last scene position within this of a sim fruit is that fruit


class BenchError(RuntimeError):
    """The benchmark cannot run (a service missing from this build, a bad seed range)."""


@dataclass
class Collected:
    """What the evaluation needs from one run, whichever way it ran."""

    summary: RunSummary | None = None
    truth: GroundTruth | None = None  # the last one
    # every fresh scene position of each track: (stamp ns, world m), in time order
    sightings: dict[int, list[tuple[int, tuple[float, float, float]]]] = field(default_factory=dict)
    sim_events: list[Any] = field(default_factory=list)
    harvest_events: list[Any] = field(default_factory=list)
    max_velocity_ratio: float = 0.0  # |q̇| / limit over every command

    def take(self, topic: str, msg: Any) -> None:
        if topic == "harvest/summary":
            self.summary = msg
        elif topic == "sim/truth":
            self.truth = msg
        elif topic == "scene/state":
            s: SceneState = msg
            for f in s.fruits:
                if f.frames_unseen == 0:
                    seen = self.sightings.setdefault(f.fruit_id, [])
                    seen.append((s.header.stamp_ns, f.position_world_m))
        elif topic == "sim/events":
            self.sim_events.append(msg)
        elif topic == "harvest/events":
            self.harvest_events.append(msg)
        elif topic == "robot/command":
            self.max_velocity_ratio = max(self.max_velocity_ratio, _velocity_ratio(msg))


def _velocity_ratio(cmd: Any) -> float:
    from services.robot.model import velocity_limits_rad_s

    lim = velocity_limits_rad_s()
    return max(
        (abs(v) / lim[i] for arm in cmd.arms.values() for i, v in enumerate(arm.velocity_rad_s)),
        default=0.0,
    )


def parse_seeds(text: str) -> list[int]:
    """'3' → [3]; '0-19' → [0..19]; '1,4,9' → [1, 4, 9]."""
    out: list[int] = []
    try:
        for part in text.split(","):
            if "-" in part:
                a, b = (int(x) for x in part.split("-", 1))
                if b < a:
                    raise BenchError(f"--seeds {text!r}: {b} < {a}")
                out += list(range(a, b + 1))
            else:
                out.append(int(part))
    except ValueError:
        raise BenchError(f"--seeds {text!r}: use A-B, A,B,C or A") from None
    return out


def parse_sets(items: Sequence[str]) -> dict[str, dict[str, Any]]:
    """``["scene.occupancy=false"]`` → ``{"scene": {"occupancy": False}}`` (values parsed as
    YAML), each service's block validated by its Settings; a BenchError names the bad item."""
    from services.registry import service_def
    from services.runtime.settings import SettingsError, load_settings, parse_overrides

    out: dict[str, dict[str, Any]] = {}
    for item in items:
        key = item.split("=", 1)[0].strip()
        service, _, leaf = key.partition(".")
        if "=" not in item or not leaf or "." in leaf:
            raise BenchError(
                f"--set {item!r}: expected SERVICE.KEY=VALUE, e.g. scene.occupancy=false"
            )
        if service not in SETTABLE:
            raise BenchError(f"--set {item!r}: unknown service {service!r} ({', '.join(SETTABLE)})")
        try:
            value = parse_overrides([f"{leaf}={item.split('=', 1)[1]}"])[leaf]
        except Exception as exc:  # a YAML syntax error in the value
            raise BenchError(f"--set {item!r}: {exc}") from None
        out.setdefault(service, {})[leaf] = value
    for service, block in out.items():
        try:
            load_settings(service_def(service).settings, block, service=service)
        except SettingsError as exc:
            raise BenchError(f"--set {service}.*: {exc}") from None
    return out


# ---- one run, in process -------------------------------------------------------------------
NodeFactory = Callable[[], list[Any]]  # → InprocNode list standing between sim and controller


def perception_chain(overrides: dict[str, dict[str, Any]] | None = None) -> list[Any]:
    """Detector, tracker and scene cores from the registry (their default settings)."""
    from services.registry import SERVICE_MODULES, service_def
    from services.runtime.inproc import InprocNode
    from services.runtime.settings import load_settings

    missing = [n for n in CHAIN if n not in SERVICE_MODULES]
    if missing:
        raise BenchError(
            f"the harvest needs the perception chain; not in this build: {', '.join(missing)}"
        )
    nodes = []
    for name in CHAIN:
        sd = service_def(name)
        assert sd.make_core is not None
        core = sd.make_core(load_settings(sd.settings, (overrides or {}).get(name, {})))
        nodes.append(InprocNode(name, sd.spec.inputs, core))
    return nodes


def run_inproc(
    sim_settings: dict[str, Any],
    planner_settings: dict[str, Any],
    max_s: float,
    perception: NodeFactory | None = None,
    controller_settings: dict[str, Any] | None = None,
) -> tuple[Collected, float, float]:
    """One run in one process; returns what was collected, sim seconds and wall seconds."""
    from services.controller import SERVICE as CTRL
    from services.planner import SERVICE as PLAN
    from services.runtime.inproc import InprocGraph, InprocNode
    from services.runtime.settings import load_settings
    from services.sim import SERVICE as SIM

    assert SIM.make_core and CTRL.make_core and PLAN.make_core
    sim = SIM.make_core(load_settings(SIM.settings, sim_settings))
    ctrl = CTRL.make_core(
        load_settings(CTRL.settings, {"publish_diagnostics": False, **(controller_settings or {})})
    )
    plan = PLAN.make_core(load_settings(PLAN.settings, planner_settings))
    got = Collected()
    nodes = [
        *(perception or perception_chain)(),
        InprocNode("controller", CTRL.spec.inputs, ctrl),
        InprocNode("planner", PLAN.spec.inputs, plan),
    ]
    graph = InprocGraph("sim", sim, SIM.spec.inputs, nodes, lambda _s, t, m: got.take(t, m))
    t0 = time.perf_counter()
    ticks = graph.run(plan.done, int(max_s * 1e9 / sim.s.control_period_ns))
    wall = time.perf_counter() - t0
    sim.close()
    return got, ticks * sim.s.control_period_ns * 1e-9, wall


# ---- one run, as the real stack -------------------------------------------------------------
def run_stack(
    sim_settings: dict[str, Any],
    planner_settings: dict[str, Any],
    workdir: Path,
    run_id: str,
    settings: dict[str, dict[str, Any]] | None = None,
) -> tuple[Collected, float, float]:
    """One run of the real stack (supervisor, processes, bus, recorder); evaluated from the
    recording. Endpoint: a unix socket in ``workdir``. ``settings``: the chain's and the
    controller's blocks (by service)."""
    import yaml

    from schemas.topics import TOPICS
    from services.recorder.inspect import iter_messages
    from services.supervisor.stack import load_stack
    from services.supervisor.supervisor import Supervisor

    stack_file = workdir / f"{run_id}.yaml"
    stack_file.write_text(
        yaml.safe_dump(
            {
                "name": f"bench-{run_id}",
                "mode": "lockstep",
                "master": "sim",
                "router": {"listen": [f"unixsock-stream/{workdir}/{run_id}.sock"]},
                "recording": {"enabled": True, "dir": str(workdir)},
                "services": {
                    "sim": {"settings": sim_settings},
                    **{n: {"settings": (settings or {}).get(n, {})} for n in CHAIN},
                    "controller": {
                        "settings": {
                            "publish_diagnostics": False,
                            **(settings or {}).get("controller", {}),
                        }
                    },
                    "planner": {"main": True, "settings": planner_settings},
                },
            }
        )
    )
    sup = Supervisor(load_stack(stack_file), stack_file, run_id, quiet=True)
    t0 = time.perf_counter()
    result = sup.run()
    wall = time.perf_counter() - t0
    if result.exit_code != 0 or result.mcap is None:
        raise BenchError(f"stack run {run_id} failed: {result.failure} (log {result.log})")
    got = Collected()
    last_stamp = 0
    for m in iter_messages(result.mcap):
        t = TOPICS.get(m.topic)
        if t is None or m.derived:
            continue
        msg = t.codec.decode(m.payload)
        got.take(m.topic, msg)
        last_stamp = max(last_stamp, msg.header.stamp_ns)
    return got, last_stamp * 1e-9, wall


# ---- evaluation ------------------------------------------------------------------------------
@dataclass
class Truth:
    """Per sim fruit: whether it can be harvested at all (see ``truth_reachability``), and why
    not ("IK", "branch", "blocked"); ``reachable_ik`` is the judgement without the branches
    (IK and the fruit in the tools' way only: the definition up to 2026-11-25)."""

    reachable: dict[int, bool]
    why: dict[int, str]
    reachable_ik: dict[int, bool] = field(default_factory=dict)
    # clear of the tree, but every such IK solution of its harvest pose or of its pre-pose
    # touches another fruit hanging at the start: reached only by pushing a neighbour aside
    # or after it is harvested (a diagnosis of the losses, not part of ``reachable``)
    crowded: dict[int, bool] = field(default_factory=dict)


# The robot (all joints, arm order) would touch a tree body: the sim's own collision test.
TouchesTree = Callable[[np.ndarray], bool]
# ... would touch a fruit other than the given sim fruit.
TouchesFruit = Callable[[np.ndarray, int], bool]


def truth_reachability(
    truth: GroundTruth,
    planner_settings: dict[str, Any],
    touches_tree: TouchesTree | None = None,
    touches_fruit: TouchesFruit | None = None,
) -> Truth:
    """A fruit is reachable when the IK reaches its harvest pose and pre-pose (true centre and
    semi-axes), some IK solution of each (the planner's sampled cutter yaws) keeps the robot off
    the trunk and branches (``touches_tree``: the sim's collision model; a dish or cutter
    that can only be put through a branch harvests with a collision), and there is an order in
    which every fruit in its tools' way is harvested before it (``clutter.blockers`` with the
    planner's clearance; fixpoint from the free ones). ``touches_fruit`` (optional) marks the
    fruit clear of the tree whose every tree-free IK solution of a pose touches a neighbour:
    ``crowded``."""
    from services.planner import SERVICE as PLAN
    from services.planner import Settings as PlannerSettings
    from services.planner.core import PlannerCore
    from services.planner.poses import FruitShape, harvest_pose, pre_pose
    from services.runtime.settings import load_settings

    settings = load_settings(PLAN.settings, planner_settings)
    assert isinstance(settings, PlannerSettings)
    core = PlannerCore(settings)  # its IK and pose settings
    ps = core.machine.pose_settings
    shapes = {
        f.fruit_id: FruitShape(np.array(f.position_world_m), f.semi_axes_m[0], f.semi_axes_m[2])
        for f in truth.fruits
    }
    why: dict[int, str] = {}
    ik_ok: set[int] = set()
    tree_ok: set[int] = set()
    crowded: set[int] = set()
    for i, shape in shapes.items():
        # the IK solutions at every sampled yaw: none for a pose is the IK's "out of reach".
        # The dish right under the tip (not the planner's dish_back_m): the judge asks whether
        # the fruit has a harvest pose, not whether the planner's choice of one works.
        sols = [
            core.kin.solutions(replace(p, basket_back_m=0.0))
            for p in (harvest_pose(shape, ps), pre_pose(shape, ps))
        ]
        if not all(sols):
            why[i] = "IK"
            continue
        ik_ok.add(i)
        free = [[s for s in p if touches_tree is None or not touches_tree(s.q_rad)] for p in sols]
        if all(free):
            tree_ok.add(i)
            if touches_fruit is not None and any(
                all(touches_fruit(s.q_rad, i) for s in p) for p in free
            ):
                crowded.add(i)
        else:
            why[i] = "branch"
    clear_ik = _clear_order(ik_ok, shapes, ps, settings.neighbour_clearance_m)
    clear = _clear_order(tree_ok, shapes, ps, settings.neighbour_clearance_m)
    for i in sorted(tree_ok - clear):
        why[i] = "blocked"
    return Truth(
        {i: i in clear for i in sorted(shapes)},
        why,
        {i: i in clear_ik for i in sorted(shapes)},
        {i: i in crowded for i in sorted(shapes)},
    )


def _clear_order(
    candidates: set[int], shapes: dict[int, Any], ps: Any, clearance_m: float
) -> set[int]:
    """The candidates that some order frees: fixpoint from those with no fruit in their tools'
    way, every other fruit (candidate or not) an obstacle until it is freed."""
    from services.planner.clutter import blockers

    done: set[int] = set()
    changed = True
    while changed:
        changed = False
        for i in sorted(candidates - done):
            others = [k for k in sorted(shapes) if k != i and k not in done]
            if not blockers(shapes[i], [shapes[k] for k in others], ps, clearance_m):
                done.add(i)
                changed = True
    return done


def _sim_fruit(p: Any, centres: dict[int, np.ndarray]) -> int | None:
    """The sim fruit whose true centre is nearest a track's position, within MATCH_M."""
    d = {i: float(np.linalg.norm(c - np.array(p))) for i, c in centres.items()}
    if not d:
        return None
    i = min(d, key=lambda k: (d[k], k))
    return i if d[i] <= MATCH_M else None


def _track_fruit(
    got: Collected, track_id: int, centres: dict[int, np.ndarray], at_ns: int | None = None
) -> int | None:
    """The sim fruit a track was on at ``at_ns``: its sighting nearest that time that lies on a
    fruit (a harvested fruit's track is later seen in the dish or falling, and a tracker may
    re-use the ID for another fruit later). Without a time: its last sighting on a fruit."""
    seen = got.sightings.get(track_id)
    if not seen:
        return None
    t = seen[-1][0] if at_ns is None else at_ns
    for _stamp, p in sorted(seen, key=lambda s: (abs(s[0] - t), -s[0])):
        i = _sim_fruit(p, centres)
        if i is not None:
            return i
    return None


TARGET_ENDS = ("fruit_collected", "fruit_dropped", "fruit_skipped", "fruit_lost", "run_finished")


def _target_windows(got: Collected, centres: dict[int, np.ndarray]) -> list[tuple[int, int, int]]:
    """(start ns, end ns, sim fruit) of each harvest attempt: from its selection (or a
    re-plan onto another fruit) to its outcome."""
    windows: list[tuple[int, int, int]] = []
    current: tuple[int, int] | None = None  # (start ns, sim fruit)
    for ev in got.harvest_events:
        t = ev.header.stamp_ns
        starts = ev.event in ("fruit_selected", "replanned") and ev.fruit_id is not None
        on = _track_fruit(got, ev.fruit_id, centres, t) if starts else None
        if on is not None:
            if current is None or ev.event == "fruit_selected":
                if current is not None:
                    windows.append((current[0], t, current[1]))
                current = (t, on)
        elif ev.event in TARGET_ENDS and current is not None and _ends(got, ev, current, centres):
            windows.append((current[0], t, current[1]))
            current = None
    if current is not None:
        windows.append((current[0], 2**62, current[1]))
    return windows


def _ends(
    got: Collected, ev: Any, current: tuple[int, int], centres: dict[int, np.ndarray]
) -> bool:
    """``ev`` (an outcome) ends the attempt ``current`` (start ns, sim fruit): it names no
    fruit (the run's end) or that fruit; not another fruit's (a fruit deferred meanwhile)."""
    if ev.fruit_id is None:
        return True
    on = _track_fruit(got, ev.fruit_id, centres, ev.header.stamp_ns)
    return on is None or on == current[1]


def _phases(events: Sequence[Any]) -> tuple[list[int], list[str]]:
    """Stamps (ns) and phases entered of the planner's phase changes, in time order."""
    changes = [e for e in events if e.event == "phase_changed"]
    return [e.header.stamp_ns for e in changes], [e.phase_to for e in changes]


def _phase_at(phases: tuple[list[int], list[str]], t_ns: int) -> str:
    i = bisect.bisect_right(phases[0], t_ns)
    return phases[1][i - 1] if i else "idle"


def body_kind(name: str) -> str:
    """What a robot touched, from the sim's body name: trunk, branch or fruit."""
    if name.startswith("branch_"):
        return "branch"
    if name.startswith("fruit_"):
        return "fruit"
    return name


EPISODE_GAP_NS = 500_000_000  # a pair touching again within 0.5 s is the same contact episode


def _contacts(got: Collected, centres: dict[int, np.ndarray]) -> dict[str, Any]:
    """Robot contacts (sim events 'collision', each begun contact once), split: with the fruit
    being harvested at the time (the tools are meant to touch it: cutting at its peduncle, the
    dish under it) and with anything else (trunk, branches, other fruit hanging): the latter
    are the collisions. Those are split again by what was touched and by the planner's phase
    when the contact began, and counted as *episodes* too: a (link, body) pair that touches
    again within ``EPISODE_GAP_NS`` of its last contact ending (a link grazing a branch
    flickers) is one episode, and as *first touches*: a body no link had touched before in the
    run (what the felt spheres cannot have prevented). Diagnostics: ``collisions`` stays the
    figure."""
    windows = _target_windows(got, centres)
    phases = _phases(got.harvest_events)
    by_kind: Counter[str] = Counter()
    by_phase: Counter[str] = Counter()
    last_end: dict[tuple[str, str], int] = {}
    touched: set[str] = set()
    target = episodes = first = 0
    for e in got.sim_events:
        if e.kind != "collision":
            continue
        t, pair = e.header.stamp_ns, (e.body_a, e.body_b)
        if "began" not in e.detail:
            last_end[pair] = t
            continue
        fruit = [w[2] for w in windows if w[0] <= t <= w[1]]
        new_body = e.body_b not in touched
        touched.add(e.body_b)
        if fruit and e.body_b == f"fruit_{fruit[0]}":
            target += 1
            continue
        by_kind[body_kind(e.body_b)] += 1
        by_phase[_phase_at(phases, t)] += 1
        episodes += pair not in last_end or t - last_end[pair] > EPISODE_GAP_NS
        first += new_body
    return {
        "collisions": sum(by_kind.values()),
        "target_contacts": target,
        "collision_episodes": episodes,
        "collisions_first_touch": first,
        "collisions_by_kind": dict(sorted(by_kind.items())),
        "collisions_by_phase": dict(sorted(by_phase.items())),
    }


HIDDEN_SHARE = 0.05  # a fruit this little visible at the start is "hidden" when never detected
# Why a reachable fruit was not harvested, from its record: (outcome, phrase in the planner's
# reason) → fate; the first that matches wins. The phrases are the planner's own (machine.py).
FATE_RULES: tuple[tuple[str, str, str], ...] = (
    ("unreachable", "approach no progress", "stalled_approach"),
    ("unreachable", "approach timed out", "stalled_approach"),
    ("unreachable", "harvest no progress", "stalled_harvest"),
    ("unreachable", "harvest timed out", "stalled_harvest"),
    ("unreachable", "blocked by", "blocked"),
    ("unreachable", "out of reach", "out_of_reach"),
    ("unreachable", "a branch in the tools' way", "branch_refused"),
    ("unreachable", "a fruit the detector has not found in the tools' way", "unseen_fruit_refused"),
    ("unreachable", "something the arms felt in the tools' way", "felt_refused"),
    ("cut_failed", "", "cut_failed"),
    ("dropped", "", "dropped"),
    ("lost", "", "lost"),
    ("pending", "", "pending"),
)
FATES = (
    "harvested",
    *dict.fromkeys(f for _o, _p, f in FATE_RULES),
    "not_detected",
    "not_detected_hidden",
    "other",
)


def fate_of(outcome: str | None, reason: str, visible_share: float) -> str:
    """One of FATES for a reachable fruit that was not harvested: its record's outcome and
    reason, or (no record) never detected, hidden or not at the start."""
    if outcome is None:
        return "not_detected_hidden" if visible_share < HIDDEN_SHARE else "not_detected"
    for o, phrase, fate in FATE_RULES:
        if outcome == o and phrase in reason:
            return fate
    return "other"


def _fates(rows: list[dict[str, Any]]) -> dict[str, int]:
    """How many reachable fruit ended in each fate (every key of FATES, zeros included)."""
    out = dict.fromkeys(FATES, 0)
    for row in rows:
        out[row["fate"]] += 1
    return out


def _reachable_rows(
    records: dict[int, Any], reachable: list[int], collected: set[int], truth: GroundTruth
) -> list[dict[str, Any]]:
    """One row per reachable fruit: the sim's fruit, the planner's track ID (None: never
    detected), its fate and the record's reason (diagnosis)."""
    visible = {f.fruit_id: f.visible_fraction for f in truth.fruits}
    rows = []
    for i in reachable:
        r = records.get(i)
        if i in collected:
            fate = "harvested"
        elif r is None:
            fate = fate_of(None, "", visible[i])
        else:
            fate = fate_of(r.outcome, r.reason, visible[i])
        rows.append(
            {
                "fruit": i,
                "track": r.fruit_id if r is not None else None,
                "fate": fate,
                "reason": r.reason if r is not None else "",
            }
        )
    return rows


def retraces(events: Sequence[Any]) -> dict[str, int]:
    """Retraces after a stall (the skip event says "retracing"), and those that stopped short
    of where the attempt began (the phase change that ends them says "retrace stuck / timed
    out")."""
    started = sum(1 for e in events if e.event == "fruit_skipped" and "retracing" in e.reason)
    short = sum(1 for e in events if e.event == "phase_changed" and e.reason.startswith("retrace "))
    return {"retraces": started, "retraces_short": short}


AT_NOTHING_M = 0.05  # a cut this far from every peduncle closed on no fruit at all
CUT_KEYS = ("cuts", "cuts_missed", "cuts_at_nothing", "retry_cuts", "retry_cuts_hit")


def cuts(sim_events: Sequence[Any]) -> dict[str, int]:
    """The shears' closings as the sim judged them: hits, misses, misses at nothing (more than
    ``AT_NOTHING_M`` from every peduncle: a phantom target), and retries: a cut near a fruit
    whose last cut missed it narrowly, and those that hit (a retry from the same estimate
    closes where the first cut missed)."""
    from services.sim.fruits import missed_distance_m

    out = dict.fromkeys(CUT_KEYS, 0)
    near_miss: set[int | None] = set()  # fruit whose last cut missed them narrowly
    for e in sim_events:
        if e.kind not in ("cut", "cut_missed"):
            continue
        hit = e.kind == "cut"
        d_m = None if hit else missed_distance_m(e.detail)
        far = not hit and (d_m is None or d_m > AT_NOTHING_M)
        out["cuts"] += 1
        out["cuts_missed"] += not hit
        out["cuts_at_nothing"] += far
        if e.fruit_id in near_miss:
            out["retry_cuts"] += 1
            out["retry_cuts_hit"] += hit
        if hit:
            near_miss.discard(e.fruit_id)
        elif not far:
            near_miss.add(e.fruit_id)
    return out


def approach_plans(events: Sequence[Any]) -> dict[str, int]:
    """Planned approaches (plan_approach): paths found and followed, none found, paths left
    short of their end. A plan is reported by the phase change into the approach ('always')
    or a ``replanned`` event (after a stall, or planned again): "planned joint path …" or "no
    planned path …"; a path left says "planned path stuck / timed out …"."""
    reasons = [
        e.reason
        for e in events
        if e.event == "replanned" or (e.event == "phase_changed" and e.phase_to == "approach")
    ]
    return {
        "approach_paths": sum(1 for r in reasons if "planned joint path" in r),
        "approach_no_path": sum(1 for r in reasons if "no planned path" in r),
        "approach_paths_short": sum(1 for r in reasons if r.startswith("planned path ")),
    }


def crowd_picks(events: Sequence[Any]) -> dict[str, int]:
    """Selections ``crowd_first`` made: a neighbour taken before the nearest fruit, whose arms
    would touch it ("before #…, the nearest …")."""
    return {
        "crowd_first_picks": sum(
            1 for e in events if e.event == "fruit_selected" and e.reason.startswith("before #")
        )
    }


def evaluate(got: Collected, first_truth: GroundTruth, judged: Truth) -> dict[str, Any]:
    """Figures of one run against the truth (the first frame's fruit, before any cut, and
    ``judged`` on it: ``first_frame``)."""
    s, last = got.summary, got.truth
    reach = judged.reachable
    centres = {f.fruit_id: np.array(f.position_world_m) for f in first_truth.fruits}
    outcome: dict[int, str] = {}  # sim fruit → the planner's outcome
    record: dict[int, Any] = {}  # sim fruit → its record (an attempted one before the others)
    for r in s.fruits if s is not None else ():
        when = r.started_ns if r.started_ns is not None else r.finished_ns  # where it hung
        i = _track_fruit(got, r.fruit_id, centres, when)
        if i is not None:
            outcome.setdefault(i, r.outcome)
            if i not in record or (record[i].started_ns is None and r.started_ns is not None):
                record[i] = r
    collected = {e.fruit_id for e in got.sim_events if e.kind == "collected"}
    reachable = sorted(i for i, ok in reach.items() if ok)
    unreachable = sorted(i for i, ok in reach.items() if not ok)
    detected = sorted(outcome)
    reported_unreachable = {i for i, o in outcome.items() if o == "unreachable"}
    cycles = [
        r.duration_s
        for r in (s.fruits if s is not None else ())
        if r.outcome == "harvested" and r.duration_s is not None
    ]
    harvested_reachable = len(collected & set(reachable))
    fates = _reachable_rows(record, reachable, collected, first_truth)
    reachable_ik = {i for i, ok in judged.reachable_ik.items() if ok}
    counters = last.counters if last is not None else None
    return {
        "fruit": len(reach),
        "reachable": len(reachable),
        "detected": len(detected),
        "reachable_detected": len(set(reachable) & set(detected)),
        "harvested": len(collected),
        "harvested_reachable": harvested_reachable,
        "success_rate": harvested_reachable / len(reachable) if reachable else 1.0,
        "unreachable_true": len(unreachable),
        "unreachable_blocked": sum(1 for i in unreachable if judged.why.get(i) == "blocked"),
        "unreachable_branch": sum(1 for i in unreachable if judged.why.get(i) == "branch"),
        "reachable_ik": len(reachable_ik),
        "harvested_reachable_ik": len(collected & reachable_ik),
        "unreachable_reported": len(reported_unreachable),
        "unreachable_correct": len(reported_unreachable & set(unreachable)),
        "reachable_called_unreachable": len(reported_unreachable - set(unreachable)),
        "reachable_crowded": sum(1 for i in reachable if judged.crowded.get(i)),
        "lost_crowded": sum(1 for i in reachable if judged.crowded.get(i) and i not in collected),
        "dropped": sum(1 for e in got.sim_events if e.kind == "dropped"),
        **_contacts(got, centres),
        "contact_ticks": counters.contact_ticks if counters is not None else None,
        "commands_clamped": counters.commands_clamped if counters is not None else None,
        "max_velocity_ratio": round(got.max_velocity_ratio, 4),
        "cycles_s": [round(c, 3) for c in cycles],
        "reachable_fates": _fates(fates),
        "reachable_lost": [r for r in fates if r["fate"] != "harvested"],
        **retraces(got.harvest_events),
        **approach_plans(got.harvest_events),
        **crowd_picks(got.harvest_events),
        **cuts(got.sim_events),
        "summary": s.model_dump(mode="json", exclude={"header"}) if s is not None else None,
    }


# ---- the benchmark ---------------------------------------------------------------------------
@dataclass
class BenchConfig:
    scenario: str
    seeds: list[int]
    orders: Sequence[str] = ("nearest", "planned")
    fruit_count: int | None = None
    mode: str = "inproc"
    max_s: float = 240.0
    perception: NodeFactory | None = None  # tests: a stand-in chain (module-level with jobs)
    settings: dict[str, dict[str, Any]] = field(default_factory=dict)  # --set, by service
    jobs: int = 1  # inproc runs at once (processes)
    events_dir: Path | None = None  # --events-out: each run's events as JSON lines here
    rows_path: Path | None = None  # --rows: each row kept there, and reused (bench_rows.py)
    code: str | None = None  # the code the rows are of (None: git's; tests set it)


def run_harvest_bench(
    cfg: BenchConfig, progress: Callable[[str], None] | None = None
) -> dict[str, Any]:
    """Every (order, seed) run, ``cfg.jobs`` at a time (inproc runs in spawned processes: each
    run is deterministic on its own, so the rows do not depend on how many run at once)."""
    workdir = Path(tempfile.mkdtemp(prefix="bench-harvest-"))
    runs_all = [(order, seed) for order in cfg.orders for seed in cfg.seeds]
    say = progress or (lambda _line: None)
    key = run_key(
        cfg.scenario,
        cfg.mode,
        cfg.fruit_count,
        cfg.max_s,
        cfg.settings,
        cfg.code if cfg.code is not None else code_version(),
    )
    rows = _rows_kept(cfg, key, runs_all, say)
    todo = [k for k in runs_all if k not in rows]

    def done(row: dict[str, Any]) -> None:
        rows[(row["order"], row["seed"])] = row
        if cfg.rows_path is not None:
            append_row(cfg.rows_path, key, row)
        say(
            f"{row['order']} seed {row['seed']}: {row['harvested']}/{row['reachable']} "
            f"harvested, {row['collisions']} collisions (+{row['target_contacts']} with the "
            f"target), {row['sim_s']:.1f} s sim in {row['wall_s']:.0f} s"
        )

    parallel = cfg.jobs > 1 and cfg.mode == "inproc" and len(todo) > 1
    if parallel:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = multiprocessing.get_context("spawn")  # no forked torch or pybullet state
        with ProcessPoolExecutor(min(cfg.jobs, len(todo)), mp_context=ctx) as pool:
            futures = [pool.submit(run_one, cfg, order, seed, workdir) for order, seed in todo]
            for fut in as_completed(futures):
                done(fut.result())
    else:
        for order, seed in todo:
            done(run_one(cfg, order, seed, workdir))
    runs = [rows[k] for k in runs_all]
    return {
        "scenario": cfg.scenario,
        "seeds": cfg.seeds,
        "mode": cfg.mode,
        "fruit_count": cfg.fruit_count,
        "settings": cfg.settings,
        "code": key["code"],
        "policies": {o: aggregate([r for r in runs if r["order"] == o]) for o in cfg.orders},
        "runs": runs,
    }


def _rows_kept(
    cfg: BenchConfig,
    key: dict[str, Any],
    runs: list[tuple[str, int]],
    say: Callable[[str], None],
) -> dict[tuple[str, int], dict[str, Any]]:
    """The rows of ``runs`` that ``cfg.rows_path`` already holds under ``key``."""
    if cfg.rows_path is None:
        return {}
    kept = read_rows(cfg.rows_path)
    for line in kept.skipped:
        say(line)
    if str(key["code"]).endswith(DIRTY):
        say(f"{cfg.rows_path}: the code has uncommitted changes: rows are written, none reused")
    reuse = reusable(kept, key)
    got = {k: reuse[k] for k in runs if k in reuse}
    for order, seed in got:
        say(f"{order} seed {seed}: the row in {cfg.rows_path}")
    return got


def from_rows(paths: list[Path], progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The bench's result from rows files (``--from-rows``): no run, the table of the rows."""
    try:
        key, runs, skipped = combined(paths)
    except RowsError as exc:
        raise BenchError(str(exc)) from None
    for line in skipped:
        (progress or (lambda _line: None))(line)
    orders = list(dict.fromkeys(r["order"] for r in runs))
    return {
        "scenario": key["scenario"],
        "seeds": sorted({r["seed"] for r in runs}),
        "mode": key["mode"],
        "fruit_count": key["fruit_count"],
        "settings": key["settings"],
        "code": key["code"],
        "policies": {o: aggregate([r for r in runs if r["order"] == o]) for o in orders},
        "runs": runs,
    }


def run_one(cfg: BenchConfig, order: str, seed: int, workdir: Path) -> dict[str, Any]:
    """One seed with one order policy: run, then judged on the truth (the row of the table)."""
    sets = cfg.settings
    sim_s: dict[str, Any] = {"scenario": cfg.scenario, "seed": seed}
    if cfg.fruit_count is not None:
        sim_s["fruit_count"] = cfg.fruit_count
    sim_s.update(sets.get("sim", {}))
    plan_s = {"order": order, "scenario": cfg.scenario, "seed": seed}
    plan_s.update(sets.get("planner", {}))
    if cfg.mode == "stack":
        got, sim_t, wall = run_stack(sim_s, plan_s, workdir, f"{order}-{seed}", sets)
    else:
        perception = cfg.perception or (lambda: perception_chain(sets))
        got, sim_t, wall = run_inproc(sim_s, plan_s, cfg.max_s, perception, sets.get("controller"))
    row: dict[str, Any] = {
        "order": order,
        "seed": seed,
        "sim_s": round(sim_t, 3),
        "wall_s": round(wall, 2),
    }
    row["rtf"] = round(sim_t / wall, 3) if wall > 0 else None
    row.update(evaluate(got, *first_frame(sim_s, plan_s)))
    if cfg.events_dir is not None:
        write_events(got, cfg.events_dir / f"{order}-{seed}.jsonl")
    return row


def write_events(got: Collected, path: Path) -> None:
    """The run's harvest and sim events as JSON lines in stamp order (a harvest event before a
    sim event of the same stamp: the planner's tool command comes first), one
    ``{"topic": …, **message}`` object per line: for diagnosis (``jq``, pandas)."""
    import json

    tagged = [("harvest/events", e) for e in got.harvest_events]
    tagged += [("sim/events", e) for e in got.sim_events]
    tagged.sort(key=lambda te: te[1].header.stamp_ns)  # stable: harvest first at a tie
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w") as f:
        for topic, e in tagged:
            f.write(json.dumps({"topic": topic, **e.model_dump(mode="json")}) + "\n")


def first_frame(sim_s: dict[str, Any], plan_s: dict[str, Any]) -> tuple[GroundTruth, Truth]:
    """The truth of the scenario's first frame (every fruit on the tree), from a fresh sim, and
    the fruit judged on it with that sim's collision model (``truth_reachability``)."""
    from services.runtime.settings import load_settings
    from services.sim import SERVICE as SIM

    assert SIM.make_core is not None
    sim = SIM.make_core(load_settings(SIM.settings, sim_s))
    try:
        (group, *_rest) = sim.emit()
        truth = next(m for t, m in group if t == "sim/truth")
        physics = sim.physics
        return truth, truth_reachability(
            truth,
            plan_s,
            lambda q: bool(physics.tree_contacts_at(q)),
            lambda q, i: bool(physics.fruit_contacts_at(q, i)),
        )
    finally:
        sim.close()


def _sum_counts(counts: Iterable[dict[str, int]]) -> dict[str, int]:
    total: Counter[str] = Counter()
    for c in counts:
        total.update(c)
    return dict(sorted(total.items()))


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Totals over seeds for one policy."""
    if not rows:
        return {}
    tot = {
        k: sum(r.get(k) or 0 for r in rows)
        for k in (
            "fruit",
            "reachable",
            "detected",
            "reachable_detected",
            "harvested",
            "harvested_reachable",
            "unreachable_true",
            "unreachable_blocked",
            "unreachable_branch",
            "reachable_ik",
            "harvested_reachable_ik",
            "unreachable_reported",
            "unreachable_correct",
            "reachable_called_unreachable",
            "reachable_crowded",
            "lost_crowded",
            "dropped",
            "collisions",
            "collision_episodes",
            "collisions_first_touch",
            "target_contacts",
            "commands_clamped",
            "retraces",
            "retraces_short",
            "approach_paths",
            "approach_no_path",
            "approach_paths_short",
            "crowd_first_picks",
            *CUT_KEYS,
        )
    }
    if any("collisions_first_touch" not in r for r in rows):
        tot["collisions_first_touch"] = None  # rows from before it was counted: not 0
    cycles = [c for r in rows for c in r["cycles_s"]]
    sim_s, wall_s = sum(r["sim_s"] for r in rows), sum(r["wall_s"] for r in rows)
    return {
        **tot,
        "runs": len(rows),
        "reachable_fates": {k: sum(r["reachable_fates"].get(k, 0) for r in rows) for k in FATES},
        "collisions_by_kind": _sum_counts(r.get("collisions_by_kind", {}) for r in rows),
        "collisions_by_phase": _sum_counts(r.get("collisions_by_phase", {}) for r in rows),
        "success_rate": tot["harvested_reachable"] / tot["reachable"] if tot["reachable"] else 1.0,
        "success_rate_ik": (
            tot["harvested_reachable_ik"] / tot["reachable_ik"] if tot["reachable_ik"] else 1.0
        ),
        "unreachable_identified": (
            tot["unreachable_correct"] / tot["unreachable_true"] if tot["unreachable_true"] else 1.0
        ),
        "median_s_per_fruit": statistics.median(cycles) if cycles else None,
        "s_per_fruit_total": sim_s / tot["harvested"] if tot["harvested"] else None,
        "max_velocity_ratio": max(r["max_velocity_ratio"] for r in rows),
        "sim_s": round(sim_s, 2),
        "wall_s": round(wall_s, 1),
        "rtf": round(sim_s / wall_s, 3) if wall_s else None,
    }


def seed_ranges(seeds: Sequence[int]) -> str:
    """``0-7,10,12-13``: the seeds as parse_seeds reads them back."""
    spans: list[list[int]] = []
    for s in sorted(set(seeds)):
        if spans and s == spans[-1][1] + 1:
            spans[-1][1] = s
        else:
            spans.append([s, s])
    return ",".join(f"{a}" if a == b else f"{a}-{b}" for a, b in spans)


def table(result: dict[str, Any]) -> str:
    """A plain-text table of the per-policy figures."""
    keys = (
        ("harvested", "harvested"),
        ("reachable", "reachable (truth)"),
        ("success_rate", "success rate"),
        ("unreachable_correct", "unreachable identified"),
        ("unreachable_true", "unreachable (truth)"),
        ("unreachable_blocked", "  of which blocked by fruit"),
        ("unreachable_branch", "  of which only reached through a branch"),
        ("harvested_reachable_ik", "harvested of the reachable without the branch check"),
        ("reachable_ik", "reachable without the branch check"),
        ("reachable_called_unreachable", "reachable called unreachable"),
        ("reachable_crowded", "reachable only past a neighbour"),
        ("lost_crowded", "  of which not harvested"),
        ("dropped", "dropped"),
        ("collisions", "collisions (robot contacts, target excluded)"),
        ("collision_episodes", "  as episodes (a pair again within 0.5 s: one)"),
        ("collisions_first_touch", "  of which a body's first touch in the run"),
        ("target_contacts", "contacts with the fruit being harvested"),
        ("median_s_per_fruit", "median s per harvested fruit"),
        ("s_per_fruit_total", "run s per harvested fruit"),
        ("max_velocity_ratio", "peak |q̇| / limit"),
        ("commands_clamped", "commands clamped by the sim"),
        ("retraces", "retraces after a stall"),
        ("retraces_short", "  of which stopped short"),
        ("approach_paths", "planned approach paths"),
        ("approach_paths_short", "  of which left short"),
        ("approach_no_path", "planned approaches without a path"),
        ("crowd_first_picks", "neighbours taken first (crowd_first)"),
        ("cuts", "cuts (shears closed)"),
        ("cuts_missed", "  of which missed"),
        ("cuts_at_nothing", f"  of which > {AT_NOTHING_M * 100:.0f} cm from any peduncle"),
        ("retry_cuts", "cuts after a near miss"),
        ("retry_cuts_hit", "  of which hit"),
        ("wall_s", "wall s"),
        ("rtf", "real-time factor"),
    )
    pols = result["policies"]
    lines = [
        f"{result['scenario']} seeds {seed_ranges(result['seeds'])} ({result['mode']})",
        f"{'':34}" + "".join(f"{o:>14}" for o in pols),
    ]
    for k, label in keys:
        cells = []
        for o in pols:
            v = pols[o].get(k)
            cells.append(f"{v:14.3f}" if isinstance(v, float) else f"{v!s:>14}")
        lines.append(f"{label:34}" + "".join(cells))
    lines.append("where the reachable fruit went:")
    for fate in FATES:
        cells = [f"{pols[o].get('reachable_fates', {}).get(fate, 0):>14}" for o in pols]
        lines.append(f"  {fate:32}" + "".join(cells))
    for key, title in (("collisions_by_kind", "what"), ("collisions_by_phase", "phase")):
        names = sorted({n for o in pols for n in pols[o].get(key, {})})
        if names:
            lines.append(f"collisions by {title}:")
        for n in names:
            cells = [f"{pols[o].get(key, {}).get(n, 0):>14}" for o in pols]
            lines.append(f"  {n:32}" + "".join(cells))
    return "\n".join(lines)
