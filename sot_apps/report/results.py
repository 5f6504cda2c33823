"""docs/results.md, generated from saved result JSON (``sot-apps results DIR --out docs/results.md``).

A result file is the JSON a command wrote with ``--json`` (``sot-apps eval``, ``sot-apps eval --benchmark``,
``sot-apps bench ...``) carrying a ``provenance`` record: the commands that made it, the date (UTC) and the
machine (CPU model, cores). ``sot-apps eval`` writes the record itself; :func:`stamp` adds it to the JSON of a
command that does not (``sot-apps results --stamp FILE --command CMD``). The page has one section per file, in
file-name order, each stamped with its commands, machine and date; it renders the figures as they were saved
(nothing is recomputed) and is the same for the same files.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from ..errors import InputError
from ..provenance import provenance_record

__all__ = ["Provenance", "ResultFile", "stamp", "read_results", "render_results"]

@dataclass(frozen=True)
class Provenance:
    """Where a result file comes from: the commands that made it, when (UTC) and on what machine."""

    commands: tuple[str, ...]
    date: str
    cpu: str
    cores: str
    note: str = ""


@dataclass(frozen=True)
class ResultFile:
    name: str
    kind: str                 # eval | eval-benchmark | bench-tracker | figures
    data: dict[str, Any]
    provenance: Provenance
    title: str


def _load(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(path, f"not a readable JSON file ({exc})") from None
    if not isinstance(data, dict):
        raise InputError(path, "a result file holds a JSON object")
    return data


def stamp(path: str | Path, commands: Sequence[str], date: str | None = None, note: str = "",
          title: str = "") -> None:
    """Add a ``provenance`` record (this machine; ``date`` or now; ``title``: the page's section title) to the
    result JSON ``path``, in place."""
    from ..io.atomic import write_json

    path = Path(path)
    data = _load(path)
    if not commands:
        raise InputError(path, "stamping needs the command that made the file (--command)")
    data["provenance"] = provenance_record(commands, date, note) | ({"title": title} if title else {})
    write_json(path, data)


def _provenance(path: Path, data: dict[str, Any]) -> Provenance:
    record = data.get("provenance")
    if not isinstance(record, dict):
        raise InputError(path, "no provenance record (commands, date, machine): add one with "
                               "`sot-apps results --stamp FILE --command CMD`")
    try:
        commands = tuple(str(c) for c in record["commands"])
        machine = record["machine"]
        return Provenance(commands, str(record["date"]), str(machine["cpu"]), str(machine["cores"]),
                          str(record.get("note", "")))
    except (KeyError, TypeError) as exc:
        raise InputError(path, f"provenance: missing {exc} (needs commands, date, machine.cpu, machine.cores)") \
            from None


def _kind(data: dict[str, Any]) -> str:
    if "rows" in data and "eval_config" in data:
        return "eval"
    if "tables" in data and "tracklets" in data:
        return "eval-benchmark"
    if "rows" in data and "frames_per_preset" in data:
        return "bench-tracker"
    return "figures"


def read_results(directory: str | Path) -> list[ResultFile]:
    """Every ``*.json`` of ``directory`` (file-name order) as a result file; one without provenance is an error."""
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(directory, "not a directory of result JSON files")
    out = []
    for path in sorted(directory.glob("*.json")):
        data = _load(path)
        prov = _provenance(path, data)
        title = str(data["provenance"].get("title") or path.stem)
        out.append(ResultFile(path.name, _kind(data), data, prov, title))
    if not out:
        raise InputError(directory, "no result JSON file (*.json) in it")
    return out


# ---------------------------------------------------------------------------------------------------------------
# Markdown
# ---------------------------------------------------------------------------------------------------------------

def _num(value: Any, spec: str, scale: float = 1.0) -> str:
    if value is None or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "—"
    return format(scale * value, spec)


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    align = ["---"] + ["---:"] * (len(header) - 1)
    return ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"] + ["| " + " | ".join(r) + " |" for r in rows]


def _acc_rob(m: dict[str, Any], std: dict[str, Any] | None = None) -> str:
    spread = f" ± {_num(std.get('acc'), '.1f', 100)}" if std and std.get("acc") is not None else ""
    return f"{_num(m.get('acc'), '.1f', 100)}{spread} / {_num(m.get('rob'), '.1f', 100)}"


def _eval_section(data: dict[str, Any]) -> list[str]:
    rows = data["rows"]
    seeds = len(rows[0]["seeds"]) if rows else 0
    tracks = data.get("tracks", [])
    levels = [d for d in ("easy", "medium", "hard") if any(t.get("difficulty") == d for t in tracks)]
    counts = {d: sum(t.get("difficulty") == d for t in tracks) for d in levels}
    out = [f"Sequence `{data['sequence']}`, {len(tracks)} tracks "
           f"({', '.join(f'{d} {n}' for d, n in counts.items())}), {seeds} seed{'s' if seeds != 1 else ''}"
           f"{' (mean ± spread over seeds)' if seeds > 1 else ''}. Acc / Rob in %.", ""]
    header = ["row", "Acc / Rob", *(f"{d} ({counts[d]})" for d in levels), "Shape (m)", "Success", "Precision",
              "ms/frame (median)"]
    body = []
    for r in rows:
        p = r["pooled"]
        body.append([f"`{r['name']}`", _acc_rob(p, r.get("pooled_std") if seeds > 1 else None),
                     *(_acc_rob(r["by_difficulty"][d]) if d in r["by_difficulty"] else "—" for d in levels),
                     _num(p.get("shape"), ".3f"), _num(p.get("success"), ".1f"), _num(p.get("precision"), ".1f"),
                     _num(r.get("timing", {}).get("median_ms"), ".1f")])
    return out + _table(header, body)


_EXTRA = (("relock_share", "ReLock3 {} %", ".0f", 100.0), ("found_near_share", "Found30 {} %", ".0f", 100.0),
          ("heading_err_last_med_deg", "Hdg@last {}°", ".1f", 1.0))


def _benchmark_section(data: dict[str, Any]) -> list[str]:
    presets = list(data["presets"])
    seeds = len(data["seeds"])
    groups = list(data["tables"][presets[0]]) if presets else []
    out = [f"{len(data['tracklets'])} tracklets, {seeds} tracker seed{'s' if seeds != 1 else ''}"
           f"{' (Acc: mean ± spread over seeds)' if seeds > 1 else ''}. Acc / Rob in %; ReLock3: share of hidden "
           "tracklets re-locked within 3 frames of re-appearing and held to that window's end, Found30: share of far approaches found within "
           "30 m, Hdg@last: median heading error at the last frame.", ""]
    body = []
    for g in groups:
        n = data["tables"][presets[0]][g].get("n", "")
        cells = [f"{g} ({n})"]
        for p in presets:
            m = data["tables"][p].get(g, {})
            cell = f"{_num(m.get('acc'), '.1f', 100)}"
            if seeds > 1 and m.get("acc_std") is not None:
                cell += f" ± {_num(m.get('acc_std'), '.1f', 100)}"
            cell += f" / {_num(m.get('rob'), '.1f', 100)}"
            extra = [label.format(_num(m[k], spec, scale)) for k, label, spec, scale in _EXTRA if k in m]
            cells.append(cell + (f", {', '.join(extra)}" if extra and g.startswith("profile") else ""))
        body.append(cells)
    return out + _table(["group (n)", *(f"`{p}`" for p in presets)], body)


_TRACKER_COLUMNS = (("cpu_median_ms", "CPU median ms"), ("cpu_mean_ms", "CPU mean ms"), ("cpu_p90_ms", "CPU p90 ms"),
                    ("cpu_frame1_mean_ms", "frame 1 ms"), ("sweep_ground_ms", "sweep ground ms"),
                    ("offline_added_ms", "offline added ms"), ("times_online", "× online"))


def _bench_tracker_section(data: dict[str, Any]) -> list[str]:
    rows = data["rows"]
    cols = [(k, t) for k, t in _TRACKER_COLUMNS if any(k in r for r in rows)]
    body = [[f"`{r['row']}`", *(_num(r.get(k), ".2f" if k == "times_online" else ".1f") for k, _ in cols),
             _acc_rob(r)] for r in rows]
    out = [f"Sequence `{data['sequence']}`, {len(data.get('tracks', []))} tracks, {data['frames_per_preset']} "
           "tracked frames per preset; ms per frame = CPU time of `Tracker.step` on one pinned core.", ""]
    return out + _table(["row", *(t for _, t in cols), "Acc / Rob"], body)


def _figures_section(data: dict[str, Any]) -> list[str]:
    """Any other result: its numbers and labels (top level) as a two-column table."""
    body = []
    for key, value in data.items():
        if key == "provenance" or isinstance(value, (dict, list)):
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            body.append([f"`{key}`", str(value)])
        else:
            body.append([f"`{key}`", f"{value:.4g}" if isinstance(value, float) else str(value)])
    return _table(["figure", "value"], body)


_SECTIONS = {"eval": _eval_section, "eval-benchmark": _benchmark_section, "bench-tracker": _bench_tracker_section,
             "figures": _figures_section}


def render_results(results: Sequence[ResultFile], directory: str = "results", out: str = "docs/results.md") -> str:
    """The Markdown page (``sot-apps results DIRECTORY --out OUT``): how it is made, the machines, then one section
    per result file."""
    machines: dict[tuple[str, str], list[str]] = {}
    for r in results:
        machines.setdefault((r.provenance.cpu, r.provenance.cores), []).append(r.name)
    out = ["# Results", "",
           f"Generated by `sot-apps results {directory} --out {out}` from the result files in `{directory}/` "
           "(the JSON the commands below wrote with `--json`, each with the commands that made it, the machine and "
           "the date); do not edit by hand. To add or renew a figure: run its command with "
           "`--json results/NAME.json` (a command that does not record its provenance: then "
           "`sot-apps results --stamp results/NAME.json --command \"...\"`) and generate the page "
           "again. Speeds are those of the machine named; a shared machine makes them slower.",
           "", "Machines:", ""]
    out += [f"- {cpu}, {cores} cores: {', '.join(f'`{n}`' for n in names)}" for (cpu, cores), names in machines.items()]
    for r in results:
        p = r.provenance
        out += ["", f"## {r.title}", "", f"File `{directory}/{r.name}`, measured {p.date} on {p.cpu} ({p.cores} cores)"
                + (f"; {p.note}" if p.note else "") + ". Made by:", "", "```"]
        out += list(p.commands) + ["```", ""]
        out += _SECTIONS[r.kind](r.data)
    return "\n".join(out) + "\n"
