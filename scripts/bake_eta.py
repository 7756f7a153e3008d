#!/usr/bin/env python3
"""How right a bake's ETA was: reads the JSON lines of `sky bake-luts ...
--json-progress` (a file, or - for standard input) and prints the forecast
against the cost rendered, each slice's forecast against its cost, and the
predicted end (elapsed + ETA) against the real end at fractions of the
bake's wall time, with the worst error before a tenth of it (issue 12: "an
ETA that is right to 10 % before the bake is a tenth done").

    scripts/bake_eta.py progress.jsonl [--threads N]
    scripts/bake_eta.py run1.jsonl run2.jsonl ... --threads N

Given the progress of several runs of one bake (each resuming the last),
it reports each and sums their rendering time and texels.

With the farm's threads (`--threads`), and pilots that carried their
slice's forecast (`planning` events), it also prints the queue's pace
group by group of slices while it renders: the wall time between the
progress reaching a slice and the slice eight further on, times the
threads, against the forecast of those slices (the queue's slices are
cached only at its end, so their `slice` events come late). A pilot's
forecast counts the quadrature after the queue too (about 2 % of the
sunny skies' final bake), so the pace reads that much under it.

The real end is the last progress event's elapsed time, so run it on a
bake that finished; on one still running it says so and reports the
predicted end's drift instead. Standard library only.
"""
import json
import sys


def main():
    args = sys.argv[1:]
    threads = None
    if "--threads" in args:
        i = args.index("--threads")
        try:
            threads = int(args[i + 1])
        except (IndexError, ValueError):
            print("--threads needs a whole number", file=sys.stderr)
            return 2
        del args[i : i + 2]
    if not args:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    runs = []
    for path in args:
        if len(args) > 1:
            print(f"== {path}")
        events = read(path)
        if events is None:
            return 1
        runs.append(report(events, threads))
    if len(args) > 1:
        # Runs of one bake, each resuming the last: the queue's rendering
        # time (from its first progress line to its last) and texels.
        wall = sum(r[0] for r in runs)
        texels = sum(r[1] for r in runs)
        cost = f", {wall * threads:.0f} core-seconds on {threads} threads" if threads else ""
        print(f"== {len(runs)} runs: {wall:.0f} s of rendering{cost}, {texels} texels")
    return 0


def read(path):
    """The JSON events of a --json-progress file (None after an error)."""
    src = sys.stdin if path == "-" else open(path, encoding="utf-8")
    events = []
    for number, line in enumerate(src, 1):
        if line.startswith("{"):
            try:
                events.append(json.loads(line))
            except json.JSONDecodeError as e:
                print(f"{path}:{number}: not JSON: {e}", file=sys.stderr)
                return None
    return events


def report(events, threads):
    """Prints one run's report; returns its rendering seconds and texels."""
    forecast = next((e for e in events if e["event"] == "forecast"), None)
    progress = [e for e in events if e["event"] == "progress" and e.get("eta_s") is not None]
    slices = [e for e in events if e["event"] == "slice" and not e.get("cached")]
    finished = any(e["event"] in ("sky_done", "fog_done") for e in events) and progress and progress[-1]["texels_done"] >= progress[-1]["texels_total"]
    if forecast:
        print(f"forecast ({forecast['from']}): {forecast['core_seconds']:.0f} core-seconds, planning {forecast['planning_core_seconds']:.0f}")
    if slices:
        cost = sum(e["core_seconds"] for e in slices)
        planned = sum(e["forecast_core_seconds"] or 0.0 for e in slices)
        print(f"{len(slices)} slices rendered: {cost:.0f} core-seconds against {planned:.0f} forecast ({100 * (cost / planned - 1) if planned else 0:+.1f} %)")
        for e in slices:
            f = e["forecast_core_seconds"]
            if f:
                print(f"  {e['sky']}:{e['index']} (sun zenith {e['sun_zenith_deg']:.1f}°): {e['core_seconds']:.1f} against {f:.1f} ({100 * (e['core_seconds'] / f - 1):+.1f} %)")
    if threads:
        queue_pace(events, threads)
    if not progress:
        print("no progress event with an ETA")
        return (0.0, 0)
    start = progress[0]["elapsed_s"] - 0.0
    last = progress[-1]["elapsed_s"]
    ends = [(p["elapsed_s"], p["elapsed_s"] + p["eta_s"]) for p in progress]
    if finished:
        print(f"real end {last:.0f} s; predicted end against it, at a share of the wall time:")
        for q in (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 0.9):
            at = [(t, end) for t, end in ends if t >= q * last]
            if at:
                t, end = at[0]
                print(f"  {100 * q:4.0f} % (t = {t:.0f} s): {end:.0f} s ({100 * (end / last - 1):+.1f} %)")
        early = [abs(end / last - 1) for t, end in ends if t <= 0.1 * last]
        if early:
            print(f"worst before a tenth of the wall time: {100 * max(early):.1f} %")
    else:
        print(f"not finished (last progress at {last:.0f} s, {progress[-1]['texels_done']}/{progress[-1]['texels_total']} texels); the predicted end over time:")
        step = max(1, len(ends) // 10)
        for t, end in ends[::step] + [ends[-1]]:
            print(f"  t = {t:.0f} s: {end:.0f} s ({100 * (end / ends[0][1] - 1):+.1f} % against the first, at {start:.0f} s)")
    return (last - start, progress[-1]["texels_done"] - progress[0]["texels_done"])


def queue_pace(events, threads, group=8):
    """The queue's cost against its forecast, `group` slices at a time."""
    forecast = {}
    for e in events:
        if e["event"] == "planning" and e.get("forecast_core_seconds") is not None:
            forecast[(e["sky"] + (" (fog)" if e["fog"] else ""), e["index"])] = e["forecast_core_seconds"]
    first_seen, order = {}, []
    for e in events:
        if e["event"] == "progress" and e.get("sky"):
            key = (e["sky"], e["index"])
            if key not in first_seen:
                first_seen[key] = e["elapsed_s"]
                order.append(key)
    if not forecast or len(order) < 2:
        print("no per-slice forecast (planning events of pilots) or too little progress for the queue's pace")
        return
    print(f"the queue's pace on {threads} threads, {group} slices at a time (cost = wall time between reaching the first and the next group, times the threads):")
    for i in range(0, len(order) - 1, group):
        j = min(i + group, len(order) - 1)
        keys = order[i:j]
        wall = first_seen[order[j]] - first_seen[order[i]]
        planned = sum(forecast.get(k, 0.0) for k in keys)
        if planned > 0:
            name = f"{keys[0][0]}:{keys[0][1]}..{keys[-1][1]}"
            print(f"  {name}: {wall * threads:.0f} core-seconds against {planned:.0f} forecast ({100 * (wall * threads / planned - 1):+.0f} %)")


if __name__ == "__main__":
    try:
        sys.exit(main())
    except BrokenPipeError:
        sys.exit(0)
