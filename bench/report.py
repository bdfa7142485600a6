"""``bench/results.md`` from ``bench/results.json``: the figures against the targets.

.venv/bin/python bench/report.py          # rewrite results.md from results.json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import benchlib

from apc_lab import wall_clock

PAPER_MS = 7.5  # config/reference/paper.json: pdp11_45_ms_per_setpoint_n3


def _get(data: dict[str, Any], *path: str) -> Any:
    for key in path:
        if not isinstance(data, dict) or key not in data:
            return None
        data = data[key]
    return data


def _spread(s: dict[str, Any] | None, fmt: str = "{:.1f}") -> str:
    if not s or s.get("median") is None:
        return "not measured"
    return f"{fmt.format(s['median'])} [{fmt.format(s['p10'])}-{fmt.format(s['p90'])}], n={s['n']}"


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.2f} %"


def _verdict(ok: bool | None) -> str:
    return "n/a" if ok is None else ("met" if ok else "**missed**")


def target_rows(d: dict[str, Any]) -> list[tuple[str, str, str, str]]:
    """(figure, measured, target, verdict) for every performance target apc sets itself."""
    rows: list[tuple[str, str, str, str]] = []

    def us(key: str, n: str, limit: float, label: str) -> None:
        s = _get(d, key, n)
        med = s.get("median") if s else None
        rows.append(
            (
                label,
                _spread(s) + " us",
                f"<= {limit:g} us",
                _verdict(None if med is None else med <= limit),
            )
        )

    us("feedback_step_us", "3", 20, "feedback (RLS + gain) per sample, n = 3")
    us("feedback_step_us", "7", 60, "feedback (RLS + gain) per sample, n = 7")
    us("rnea_us", "6", 10, "nominal torque (RNEA), n = 6")

    def rate(path: tuple[str, ...], limit: float, label: str) -> None:
        s = _get(d, "lockstep_samples_per_s", *path)
        med = s.get("median") if s else None
        rows.append(
            (
                label,
                _spread(s, "{:.0f}") + " samples/s",
                f">= {limit:g} samples/s",
                _verdict(None if med is None else med >= limit),
            )
        )

    rate(("one_process", "recorder_on"), 2000, "lockstep, one process, recorder on")
    rate(("three_processes", "recorder_on"), 1000, "lockstep, three processes, recorder on")
    rate(("three_processes", "recorder_off"), 1000, "lockstep, three processes, recorder off")

    rt = _get(d, "realtime_late_fraction", "1000")
    lat = _get(d, "realtime_latency_us", "1000")
    if rt:
        p99 = lat.get("p99") if lat else None
        ok = rt.get("pooled") is not None and rt["pooled"] <= 0.01 and p99 is not None
        ok = ok and p99 < 1000
        rows.append(
            (
                "real time 1 kHz, three processes",
                f"late {_pct(rt.get('pooled'))}, latency p99 "
                f"{p99 if p99 is not None else 'n/a'} us",
                "<= 1 % late, p99 < 1000 us",
                _verdict(ok),
            )
        )
    one = _get(d, "realtime_variants", "1000 Hz, one process")
    if one:
        late, lat = one.get("late_fraction") or {}, one.get("latency_us") or {}
        p99 = lat.get("p99")
        ok = late.get("pooled") is not None and late["pooled"] <= 0.01
        ok = ok and p99 is not None and p99 < 1000
        rows.append(
            (
                "real time 1 kHz, one process (`composed`)",
                f"late {_pct(late.get('pooled'))}, latency p99 "
                f"{p99 if p99 is not None else 'n/a'} us",
                "<= 1 % late, p99 < 1000 us",
                _verdict(ok),
            )
        )
    for layout, label, target in (
        ("robot_node", "`robot_node`", True),
        ("late_phase", "`robot_node` activated 0.6 ms after a state", False),
    ):
        r = _get(d, "robot_loop", layout)
        if r:
            p99 = (r.get("latency_us") or {}).get("p99")
            late = r.get("late_fraction")
            ok = late is not None and late <= 0.01 and p99 is not None and p99 < 1000
            rows.append(
                (
                    f"robot path 1 kHz (`robot_sim` + {label})",
                    f"late {_pct(late)}, latency p99 {p99 if p99 is not None else 'n/a'} us",
                    "<= 1 % late, p99 < 1000 us" if target else "-",
                    _verdict(ok) if target else "-",
                )
            )
    for variant in (
        "three_processes_per_arm",
        "one_process_per_arm",
        "three_processes_per_arm_single_threaded_executor",
    ):
        ma = _get(d, "multi_arm", variant, "10")
        if ma:
            worst = ma.get("worst_arm_late_fraction")
            rows.append(
                (
                    f"10 arms at 100 Hz ({variant.replace('_', ' ')})",
                    f"worst arm {_pct(worst)} late",
                    "<= 1 % late on every arm",
                    _verdict(None if worst is None else worst <= 0.01),
                )
            )
    return rows


def _load_warning(d: dict[str, Any]) -> list[str]:
    """A warning line when other jobs used the machine's cores during the run."""
    cores = (d.get("machine") or {}).get("cores") or 1
    loads = d.get("machine_load") or {}
    busy = {part: v["other_cores"] for part, v in loads.items() if "other_cores" in v}
    if not busy:
        return []
    text = ", ".join(f"{part} {v:.2f}" for part, v in busy.items())
    line = f"Other jobs on the machine meanwhile (average cores busy, of {cores}): {text}."
    if max(busy.values()) > 0.25 * cores:
        line = f"**Caution:** {line} Timings are pessimistic and noisy."
    return [line, ""]


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out


def markdown(d: dict[str, Any]) -> str:
    lines = ["# apc benchmarks", ""]
    m = d.get("machine", {})
    lines += [
        f"Machine: {m.get('cpu', '?')}, {m.get('cores', '?')} cores, {m.get('platform', '?')}, "
        f"Python {m.get('python', '?')}, "
        + ", ".join(f"{k} {v}" for k, v in m.get("versions", {}).items()),
        "",
        f"Command: `{d.get('command', '?')}`; total wall time {d.get('total_wall_s', '?')} s; "
        f"load average before/after {d.get('load_average_before', '?')} / "
        f"{d.get('load_average_after', '?')}.",
        "",
        "Figures are medians with [p10-p90] over n repetitions (see results.json for quartiles, "
        "min/max and settings). Late fractions are pooled over all samples of all runs.",
        "",
        *_load_warning(d),
        "## Targets (moonshots)",
        "",
    ]
    lines += _table(["figure", "measured", "target", "verdict"], [list(r) for r in target_rows(d)])
    pc = d.get("paper_comparison")
    if pc:
        lines += [
            "",
            f"Paper: {pc['paper_pdp11_45_ms_per_setpoint_n3']} ms per set point (n = 3) on a "
            f"PDP-11/45; here {pc['ours_us_per_setpoint_n3']} us (RNEA + feedback), "
            f"{pc['speedup']}x faster ({pc['pdp11_us_per_op']} us vs "
            f"{pc['ours_ns_per_op']} ns per Table 1 operation).",
        ]

    if "feedback_step_us" in d:
        ns = list(d["feedback_step_us"])
        keys: list[tuple[str, str]] = [
            ("rls_update_us", "RLS update"),
            ("gain_us", "gain (Eq. 35)"),
            ("feedback_step_us", "feedback total"),
            ("rnea_us", "nominal torque (RNEA)"),
            ("pin_rnea_us", "pin.rnea alone"),
            ("plant_period_us", "plant period (4 RK4 steps of ABA)"),
            ("plant_period_crba_us", "plant period, CRBA + NLE + solve"),
            ("plant_acceleration_crba_us", "plant acceleration (CRBA+NLE+solve)"),
            ("aba_us", "pin.aba alone"),
        ]
        rows = []
        for key, label in keys:
            if key not in d:
                continue
            row = [label] + [
                f"{d[key][n]['median']:.3g} [{d[key][n]['p10']:.3g}-{d[key][n]['p90']:.3g}]"
                for n in ns
            ]
            g = _get(d, "growth_exponent", key)
            row.append(
                f"{g['measured_exponent']} ({g.get('measured_exponent_n12_24', '-')})" if g else ""
            )
            row.append(str(g.get("table1_exponent", "")) if g else "")
            rows.append(row)
        lines += ["", "## Per-sample compute (us per call, pure Python)", ""]
        lines += _table(
            [
                "operation",
                *[f"n={n}" for n in ns],
                "fitted exponent n=3-24 (n=12-24)",
                "Table 1 exponent",
            ],
            rows,
        )
        t1_rows = []
        ge = d.get("growth_exponent", {})
        for key, label in (
            ("rnea_us", "Newton-Euler"),
            ("rls_update_us", "RLS"),
            ("gain_us", "control"),
        ):
            g = ge.get(key)
            if g and "table1_ops" in g:
                t1_rows.append(
                    [label]
                    + [f"{g['table1_ops'][n]} ops, {g['ns_per_table1_op'][n]} ns/op" for n in ns]
                )
        if t1_rows:
            lines += ["", "Table 1 operation counts (mul + add) and measured ns per operation:", ""]
            lines += _table(["Table 1 row", *[f"n={n}" for n in ns]], t1_rows)

    ls = d.get("lockstep_samples_per_s")
    if ls:
        lines += ["", "## Lockstep throughput (samples/s, 3-joint PUMA, adaptive law)", ""]
        rows = []
        for layout, variants in ls.items():
            if not isinstance(variants, dict):
                continue
            for variant, s in variants.items():
                if isinstance(s, dict) and "median" in s:
                    rows.append([layout.replace("_", " "), variant.replace("_", " "), _spread(s)])
        lines += _table(["nodes", "variant", "samples/s median [p10-p90], n"], rows)

    rt = d.get("realtime_late_fraction")
    if rt:
        lat = d.get("realtime_latency_us", {})
        lines += [
            "",
            "## Real time, three processes (latency: joint_states published -> both torques in)",
            "",
        ]
        rows = []
        for hz, s in rt.items():
            ll = lat.get(hz, {})
            rows.append(
                [
                    hz,
                    _pct(s.get("pooled")),
                    f"{s.get('late', '?')}/{s.get('samples', '?')}",
                    str(ll.get("median")),
                    str(ll.get("p99")),
                    str(ll.get("max")),
                    str(s.get("achieved_hz")),
                    str(s.get("runs", "")),
                ]
            )
        lines += _table(
            [
                "rate (Hz)",
                "late",
                "late/samples",
                "median us",
                "p99 us",
                "max us",
                "achieved Hz",
                "runs",
            ],
            rows,
        )
        extra = d.get("realtime_variants")
        if extra:
            lines += ["", "Variants (same measurement):", ""]
            rows = []
            for name, v in extra.items():
                late = v.get("late_fraction", {})
                rows.append(
                    [
                        name,
                        _pct(late.get("pooled")),
                        str(v.get("latency_us", {}).get("median")),
                        str(v.get("latency_us", {}).get("p99")),
                        str(v.get("latency_us", {}).get("max")),
                        str(late.get("achieved_hz")),
                    ]
                )
            lines += _table(
                ["variant", "late", "median us", "p99 us", "max us", "achieved Hz"], rows
            )

    rl = d.get("robot_loop")
    if rl:
        lines += [
            "",
            "## Robot path at 1 kHz (`robot_sim` in its own process; latency: joint state "
            "stamp -> command at the driver)",
            "",
        ]
        rows = []
        for layout in ("robot_node", "late_phase"):
            r = rl.get(layout)
            if not isinstance(r, dict):
                continue
            lat, age, trip = (
                r.get(k) or {}
                for k in ("latency_us", "state_age_at_sample_us", "sample_to_arrival_us")
            )
            rows.append(
                [
                    layout,
                    _pct(r.get("late_fraction")),
                    f"{r.get('held_cycles', '?')}/{r.get('cycles', '?')}",
                    ", ".join(f"{100 * v:.1f}" for v in r.get("late_fraction_per_run", [])),
                    str(lat.get("median")),
                    str(lat.get("p99")),
                    f"{age.get('median')} / {age.get('p99')}",
                    f"{trip.get('median')} / {trip.get('p99')}",
                    _pct(r.get("late_after_next_cycle")),
                    str(r.get("achieved_hz")),
                    ", ".join(f"{v:.2f}" for v in r.get("max_deviation_deg_per_run", [])),
                    str((r.get("machine_load") or {}).get("other_cores", "")),
                ]
            )
        lines += _table(
            [
                "controllers",
                "late (cycles without a new command)",
                "held/cycles",
                "late per run (%)",
                "median us",
                "p99 us",
                "state age at sample us (median / p99)",
                "sample -> driver us (median / p99)",
                "after the next cycle",
                "driver Hz",
                "held within (deg, per run)",
                "other jobs (cores)",
            ],
            rows,
        )

    clock = d.get("robot_clock")
    if clock:
        lines += ["", wall_clock.markdown(clock, heading="##").rstrip()]

    ma = d.get("multi_arm")
    if ma:
        lines += ["", "## Several arms at 100 Hz in one ROS domain (late fraction per arm)", ""]
        rows = []
        for variant, per_n in ma.items():
            if not isinstance(per_n, dict):
                continue
            for n_arms, s in per_n.items():
                if not isinstance(s, dict) or "per_arm" not in s:
                    continue
                rows.append(
                    [
                        variant.replace("_", " "),
                        n_arms,
                        _pct(s.get("worst_arm_late_fraction")),
                        _pct(s.get("pooled_late_fraction")),
                        ", ".join(f"{100 * v:.1f}" for v in s["per_arm"]),
                        str(s.get("latency_us", {}).get("p99")),
                        str(s.get("processes", "")),
                    ]
                )
        cpu_rows = []
        for variant, per_n in ma.items():
            if isinstance(per_n, dict):
                for n_arms, s in per_n.items():
                    if isinstance(s, dict) and s.get("cpu"):
                        cpu_rows.append(
                            f"{variant.replace('_', ' ')} N={n_arms}: "
                            + ", ".join(
                                f"{role} {v['core_share_total']} cores, "
                                f"{v['us_per_sample_median']} us/sample"
                                for role, v in s["cpu"].items()
                            )
                        )
        lines += _table(
            [
                "layout",
                "arms",
                "worst arm",
                "all arms",
                "per arm (%)",
                "p99 latency us",
                "processes",
            ],
            rows,
        )
        if cpu_rows:
            lines += ["", "CPU (all arms together; median CPU us per sample per process):", ""]
            lines += [f"- {r}" for r in cpu_rows]
    hs = d.get("hotspots")
    if hs:
        lines += [
            "",
            "## Where a sample's time goes (cProfile, own time per sample; inflated, read shares)",
            "",
        ]
        rows = []
        for label, entry in hs.items():
            if not isinstance(entry, dict):
                continue
            profiles = {"": entry} if "buckets_us_per_sample" in entry else entry
            for role, prof in profiles.items():
                if not isinstance(prof, dict) or "buckets_us_per_sample" not in prof:
                    continue
                total = prof["total_us_per_sample"] or 1.0
                buckets = ", ".join(
                    f"{b} {100 * v / total:.0f} %"
                    for b, v in prof["buckets_us_per_sample"].items()
                    if v >= 0.02 * total
                )
                top = "; ".join(
                    f"{r['function']} {r['own_us_per_sample']:.0f}" for r in prof["top"][:4]
                )
                rows.append([f"{label} {role}".strip(), f"{total:.0f}", buckets, top])
        lines += _table(["profile", "us/sample", "shares", "top own time (us)"], rows)

    cpu_rows = []
    for where, variants in (d.get("lockstep_samples_per_s") or {}).items():
        if isinstance(variants, dict):
            for variant, s in variants.items():
                if isinstance(s, dict) and s.get("cpu_last_run"):
                    cpu_rows.append([f"lockstep {where} {variant}", s["cpu_last_run"]])
    for hz, s in (d.get("realtime_late_fraction") or {}).items():
        if s.get("cpu_last_run"):
            cpu_rows.append([f"real time {hz} Hz three processes", s["cpu_last_run"]])
    if cpu_rows:
        lines += ["", "## CPU per process (share of one core; CPU us per sample)", ""]
        lines += _table(
            ["run", "per process"],
            [
                [
                    label.replace("_", " "),
                    ", ".join(
                        f"{role} {v['core_share']:.2f} / {v['us_per_sample']} us"
                        for role, v in cpu.items()
                    ),
                ]
                for label, cpu in cpu_rows
            ],
        )

    notes = d.get("notes")
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="bench/results.md from bench/results.json")
    parser.add_argument("--json", type=Path, default=benchlib.RESULTS_JSON, help="results to read")
    parser.add_argument("--md", type=Path, default=benchlib.RESULTS_MD, help="report to write")
    args = parser.parse_args(argv)
    data = benchlib.read_results(args.json)
    if not data:
        print(f"{args.json} is missing; run bench/run_all.py", file=sys.stderr)
        return 1
    args.md.write_text(markdown(data))
    print(args.md.read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
