"""Human report and machine JSON of a benchmark run.

JSON schema ``rdm.bench/1``::

    {"schema", "command", "machine": {...}, "timer_overhead_ns": {...},
     "failed_solves_ours", "failed_solves_peers",
     "cases": {name: {"group", "title", "median_us", "p99_us", "p999_us", "max_us",
                      "mean_us", "min_us", "budget_us", "fraction_of_budget" (median / budget),
                      "fractions_of_budget": {"median", "p99", "p999", "max"}, "n",
                      "failures", "notes",
                      "target": {kind: {"limit", "value", "met"}},
                      "peers": {peer: {"median_us", "p99_us", "p999_us", "max_us",
                                       "mean_us", "min_us", "n", "fraction_of_budget",
                                       "speedup", "failures", "failure_statuses",
                                       "max_error", "error_kind", "settings"}
                                | {"skipped": reason}}}}}

``speedup`` = peer median / this measurement's median (> 1: we are faster).
"""

from __future__ import annotations

import json
from typing import Any

from rdm.bench.cases import Measurement, PeerResult, Target
from rdm.output_files import open_output

SCHEMA = "rdm.bench/1"


def peer_dict(peer: PeerResult, m: Measurement) -> dict[str, Any]:
    """JSON form of a peer beside measurement ``m``."""
    if peer.summary is None:
        return {"skipped": peer.skipped or "not run"}
    d: dict[str, Any] = peer.summary.to_dict()
    d["fraction_of_budget"] = peer.summary.median_us / m.budget_us
    d["speedup"] = peer.summary.median_us / m.summary.median_us
    d["failures"] = peer.failures
    d["max_error"] = peer.max_error
    d["error_kind"] = peer.error_kind
    d["settings"] = peer.settings
    d["failure_statuses"] = peer.failure_statuses
    return d


def target_dict(t: Target) -> dict[str, Any]:
    """JSON form of a target."""
    return {"limit": t.limit, "value": t.value, "met": t.met}


def to_json(
    measurements: list[tuple[str, Measurement]],
    machine: dict[str, Any],
    command: str,
    timer_overhead_ns: dict[str, float],
) -> dict[str, Any]:
    """The whole run as a JSON-ready dict (``measurements``: (group, measurement))."""
    cases: dict[str, Any] = {}
    for group, m in measurements:
        d: dict[str, Any] = {"group": group, "title": m.title}
        d.update(m.summary.to_dict())
        d["budget_us"] = m.budget_us
        d["fraction_of_budget"] = m.fraction_of_budget
        d["fractions_of_budget"] = {
            k: getattr(m.summary, f"{k}_us") / m.budget_us for k in ("median", "p99", "p999", "max")
        }
        d["failures"] = m.failures
        d["notes"] = list(m.notes)
        d["target"] = {t.kind: target_dict(t) for t in m.targets}
        d["peers"] = {name: peer_dict(p, m) for name, p in m.peers.items()}
        cases[m.name] = d
    ours = sum(m.failures for _, m in measurements)
    theirs = 0
    seen: set[int] = set()
    for _, m in measurements:  # peers shared by several measurements count once
        for p in m.peers.values():
            if id(p) not in seen:
                seen.add(id(p))
                theirs += p.failures
    return {
        "schema": SCHEMA,
        "command": command,
        "machine": machine,
        "timer_overhead_ns": timer_overhead_ns,
        "failed_solves_ours": ours,
        "failed_solves_peers": theirs,
        "cases": cases,
    }


def _us(x: float) -> str:
    return f"{x:9.2f}" if x < 1e5 else f"{x:9.3g}"


def _target_text(t: Target) -> str:
    mark = {True: "met", False: "MISSED", None: "n/a"}[t.met]
    if t.kind in ("median_us", "p99_us", "p999_us"):
        name = {"median_us": "median", "p99_us": "p99", "p999_us": "p99.9"}[t.kind]
        value = "-" if t.value is None else f"{t.value:.2f}"
        return f"{name} {value} <= {t.limit:g} us: {mark}"
    kind, peer = t.kind.split(":", 1)
    value = "-" if t.value is None else f"{t.value:.1f}x"
    word = "speed-up vs" if kind == "speedup_vs" else "faster than"
    return f"{word} {peer} {value} (need >= {t.limit:g}x): {mark}"


def _steal_text(share: float | None) -> str:
    if share is None:
        return "CPU steal unknown"
    return f"hypervisor steal {100 * share:.1f} % of the CPU time wanted during the run"


def format_text(doc: dict[str, Any]) -> str:
    """The report printed by ``rdm bench``."""
    mach = doc["machine"]
    lines = [
        f"rdm bench  ({doc['command']})",
        f"machine: {mach['cpu_model']}, {mach['logical_cores']} logical cores; "
        f"load average start {mach['load_average_start']} end {mach['load_average_end']}; "
        + _steal_text(mach.get("cpu_steal_share")),
        "versions: "
        + ", ".join(f"{k} {v}" for k, v in mach["versions"].items())
        + f", Python {mach['python']}; wheel profile {mach['wheel_build_profile']}; "
        f"BLAS threads {mach['thread_env'].get('OPENBLAS_NUM_THREADS')}"
        + ("" if mach["blas_threads_pinned_before_numpy"] else " (numpy loaded before pinning)"),
        f"timer: Instant pair {doc['timer_overhead_ns']['rust_median_ns']:.0f} ns, "
        f"perf_counter_ns pair {doc['timer_overhead_ns']['python_median_ns']:.0f} ns (median)",
        "",
        f"{'measurement':<22}{'median':>9}{'p99':>9}{'p99.9':>9}{'max':>9}  us"
        f"{'med/budget':>12}{'n':>9}{'fail':>6}",
    ]
    for name, c in doc["cases"].items():
        lines.append(
            f"{name:<22}{_us(c['median_us'])}{_us(c['p99_us'])}{_us(c['p999_us'])}"
            f"{_us(c['max_us'])}    {c['fraction_of_budget']:10.2e}{c['n']:9d}{c['failures']:6d}"
        )
        f = c["fractions_of_budget"]
        lines.append(
            f"    {c['title']}; budget {c['budget_us']:g} us; as % of budget: median "
            f"{100 * f['median']:.4f}, p99 {100 * f['p99']:.4f}, p99.9 {100 * f['p999']:.4f}, "
            f"max {100 * f['max']:.4f}"
        )
        for kind, t in c["target"].items():
            lines.append(
                "    target: " + _target_text(Target(kind, t["limit"], t["value"], t["met"]))
            )
        lines.extend(f"    note: {note}" for note in c["notes"])
    lines.append("")
    lines.append("peers (same run, same problems; speed-up = peer median / ours):")
    groups: dict[str, list[str]] = {}
    for name, c in doc["cases"].items():
        groups.setdefault(c["group"], []).append(name)
    for members in groups.values():
        peers = doc["cases"][members[0]]["peers"]
        for peer, p in peers.items():
            if "skipped" in p:
                lines.append(f"  {peer:<30} SKIPPED: {p['skipped']}")
                continue
            lines.append(
                f"  {peer:<30}{_us(p['median_us'])}{_us(p['p99_us'])}{_us(p['p999_us'])}"
                f"{_us(p['max_us'])}  us  n {p['n']}, failures {p['failures']}, "
                f"{p['error_kind']} {p['max_error']:.2e}"
                + (f"; failed as {p['failure_statuses']}" if p["failure_statuses"] else "")
            )
            for name in members:
                speedup = doc["cases"][name]["peers"][peer]["speedup"]
                lines.append(f"      vs {name:<22} speed-up {speedup:8.1f}x")
    lines.append("")
    lines.append(
        f"failed solves: ours {doc['failed_solves_ours']}, "
        f"peers {doc['failed_solves_peers']} (per peer above)"
    )
    return "\n".join(lines)


def write_json(doc: dict[str, Any], path: str) -> None:
    """Write ``doc`` as indented JSON ("-" for stdout)."""
    text = json.dumps(doc, indent=2, sort_keys=False, allow_nan=False)
    if path == "-":
        print(text)
    else:
        with open_output(path, "w", encoding="utf-8") as f:
            f.write(text + "\n")
