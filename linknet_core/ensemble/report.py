"""What a person reads from a study: the progress bar, the summary table, the plot."""
from __future__ import annotations

import json
import sys
import time

import numpy as np

ROW_LIMIT = 30  # a study with more members is summarised per parameter value, not member by member
VALUE_LIMIT = 20  # a parameter with more values is summarised per tenth of its values


class ProgressBar:
    """One line on stderr, redrawn after finished batches (at most 5 times a second, and at the end): members
    done, failed, retried, rate, time left."""

    REDRAW_SECONDS = 0.2

    def __init__(self, stream=None):
        self.stream = stream or sys.stderr
        self._shown = False
        self._last = -1.0

    def __call__(self, progress) -> None:
        now = time.monotonic()
        if now - self._last < self.REDRAW_SECONDS and progress.done < progress.total:
            return
        self._last = now
        frac = progress.done / progress.total
        width = 28
        bar = "#" * int(width * frac) + "-" * (width - int(width * frac))
        rate = progress.done / progress.elapsed if progress.elapsed > 0 else 0.0
        left = (progress.total - progress.done) / rate if rate > 0 else float("nan")
        line = (f"\r[{bar}] {progress.done}/{progress.total} members, {progress.failed} failed, "
                f"{progress.retried} retried, {rate:.1f}/s on {progress.workers} worker thread(s), "
                f"~{left:.0f} s left ")
        self.stream.write(line)
        self.stream.flush()
        self._shown = True

    def close(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()


def _varied(ds) -> list[str]:
    return json.loads(ds.attrs.get("varied", "[]"))


def _fmt(value) -> str:
    if isinstance(value, (str, np.str_)):
        return str(value)
    value = float(value)
    return "nan" if not np.isfinite(value) else f"{value:.6g}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(header, widths)),
             "  ".join("-" * w for w in widths)]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in rows]
    return "\n".join(lines)


def accuracy_note(ds) -> str | None:
    """The members whose estimated error exceeds their goal (linknet_core.accuracy), in words, or None."""
    if "error_estimate" not in ds or "error_goal" not in ds:
        return None
    ok = ds["status"].values.astype(str) == "ok"
    estimate, goal = ds["error_estimate"].values, ds["error_goal"].values
    over = np.flatnonzero(ok & (estimate > goal))  # NaN (not estimated, or an FMU's goal) compares False
    if not over.size:
        return None
    worst = int(over[np.argmax(estimate[over] / goal[over])])
    return (f"{over.size} of {int(ok.sum())} members' estimated position error exceeds their goal (member {worst}: "
            f"{estimate[worst]:.3g} m against {goal[worst]:.3g} m). Tighten rtol (or the step); docs/accuracy.md")


def summary(ds) -> str:
    """The study in a few lines: what ran, and the quantities of interest (largest tension, final tip
    position) against the varied parameters: member by member for small studies, else per value of each
    parameter (min / mean / max over the other members); then failures and retries."""
    names = _varied(ds)
    status = ds["status"].values.astype(str)
    ok = status == "ok"
    tip = f'tip = mass {ds.attrs.get("tip_mass")} ("{ds.attrs.get("tip_name")}")'
    lines = [f'{ds.attrs.get("scene_name")}: {ds.sizes["member"]} members through the '
             f'{ds.attrs.get("runs_through")}, t_end = {ds.attrs.get("t_end"):g} s, {ds.attrs.get("solver")}; '
             f'{int(ok.sum())} ok, {int((status == "failed").sum())} failed, {int((status == "not run").sum())} '
             f'not run, {int(ds["retried"].values.sum())} retried'
             + (f', {int((status == "missing").sum())} missing (rebuilt from {ds.attrs["recovered_from"]}: no shard '
                f'held them)' if (status == "missing").any() else ""),
             f'  engine: {ds.attrs.get("engine")}; {ds.attrs.get("wall_seconds", float("nan")):.2f} s wall and '
             f'first result after {ds.attrs.get("first_result_seconds", float("nan")):.2f} s (engine start included), '
             f'{ds.attrs.get("members_per_second", float("nan")):.1f} members/s once running', ""]
    by_client = int(ds.attrs.get("members_written_by_client", 0))
    if by_client:  # a cluster whose workers do not see the study's folder: all trajectories through one process
        lines.insert(2, f"  trajectories: the client wrote those of {by_client} member(s), not their workers "
                        f"({ds.attrs.get('client_shard_reason')}); workers that see the study's folder write their own")
    note = accuracy_note(ds)
    if note:
        lines.insert(2, f"  WARNING: {note}")
    elif "error_estimate" in ds and ok.any() and np.isfinite(ds["error_estimate"].values[ok]).any():
        lines.insert(2, f"  estimated position error: {np.nanmax(ds['error_estimate'].values[ok]):.3g} m at most, every "
                        "member within its goal")
    max_t, tip_final = ds["max_tension"].values, ds["tip_final"].values
    qoi_header = ["max T [N]", "link", "tip x [m]", "tip z [m]"]
    if ds.sizes["member"] <= ROW_LIMIT or not names:
        rows = []
        for m in range(ds.sizes["member"]) if ds.sizes["member"] <= ROW_LIMIT else []:
            params = [_fmt(ds[n].values[m]) for n in names]
            qoi = ([_fmt(max_t[m]), str(int(ds["max_tension_link"].values[m])), _fmt(tip_final[m, 0]),
                    _fmt(tip_final[m, 2])] if ok[m] else ["", "", "", ""])
            rows.append([str(m)] + params + qoi + [status[m]])
        if rows:
            lines.append(f"quantities of interest ({tip}):")
            lines.append(_table(["member"] + names + qoi_header + ["status"], rows))
    else:
        lines.append(f"quantities of interest ({tip}), min / mean / max over the members with each value "
                     f"(or in each tenth of the values, when there are more than {VALUE_LIMIT}):")
        for name in names:
            rows = []
            for label, sel in _groups(ds[name].values):
                sel = sel & ok
                rows.append([label, str(int(sel.sum()))] + [_spread(q[sel]) for q in
                                                            (max_t, tip_final[:, 0], tip_final[:, 2])])
            lines.append(_table([name, "ok"] + ["max T [N]", "tip x [m]", "tip z [m]"], rows))
            lines.append("")
    failed = np.flatnonzero(status == "failed")
    if failed.size:
        errors = ds["error"].values.astype(str)
        groups: dict[str, list[int]] = {}
        for m in failed:
            groups.setdefault(errors[m], []).append(int(m))
        lines.append(f"failed members ({failed.size}, {len(groups)} distinct error(s)):")
        for error, members in list(groups.items())[:10]:
            setting = ", ".join(f"{n}={_fmt(ds[n].values[members[0]])}" for n in names)
            which = f"member {members[0]} ({setting})" if len(members) == 1 else f"members {_ranges(members)}"
            lines.append(f"  {which}: {error[:300]}")
        if len(groups) > 10:
            lines.append(f"  ... and {len(groups) - 10} more errors (the file's 'error' variable has them all)")
    retried = np.flatnonzero(ds["retried"].values)
    if retried.size:
        lines.append(f"retried after a worker died: members {_ranges(retried)}")
    return "\n".join(lines).rstrip()


def _groups(values):
    """(label, members) per distinct value, or per tenth of the sorted values when there are more than
    VALUE_LIMIT distinct numbers (Monte Carlo samples, fine grids)."""
    distinct = list(dict.fromkeys(values.tolist()))
    if len(distinct) <= VALUE_LIMIT or not np.issubdtype(values.dtype, np.number):
        return [(_fmt(v), values == v) for v in distinct[:VALUE_LIMIT]]
    edges = np.quantile(values, np.linspace(0, 1, 11))
    bins = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, 9)
    return [(f"{_fmt(values[bins == b].min())} .. {_fmt(values[bins == b].max())}", bins == b)
            for b in range(10) if (bins == b).any()]


def _spread(q) -> str:
    q = q[np.isfinite(q)]
    return "" if q.size == 0 else f"{q.min():.4g} / {q.mean():.4g} / {q.max():.4g}"


def _ranges(members) -> str:
    """[1, 2, 3, 7] -> '1-3, 7'."""
    out, start = [], None
    for i, m in enumerate(members):
        if start is None:
            start = m
        if i + 1 == len(members) or members[i + 1] != m + 1:
            out.append(f"{start}-{m}" if m != start else f"{m}")
            start = None
    return ", ".join(out)


def plot(ds, path) -> None:
    """The quantities of interest against each varied parameter (one column per parameter; points coloured
    by the next parameter when there is one), and the tip's height against time for up to 200 members."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = _varied(ds) or ["member"]
    ok = ds["status"].values.astype(str) == "ok"
    quantities = [("max_tension", None, "max tension [N]"), ("tip_final", 0, "final tip x [m]"),
                  ("tip_final", 2, "final tip z [m]")]
    has_path = "X" in ds
    rows = len(quantities) + (1 if has_path else 0)
    fig, axes = plt.subplots(rows, len(names), figsize=(4.2 * len(names), 2.8 * rows), squeeze=False)
    for col, name in enumerate(names):
        x = ds[name].values
        colour_by = names[col + 1] if col + 1 < len(names) else (names[0] if len(names) > 1 else None)
        colours = ds[colour_by].values if colour_by else None
        numeric_colours = colours is not None and np.issubdtype(np.asarray(colours).dtype, np.number)
        for row, (var, axis, label) in enumerate(quantities):
            ax = axes[row, col]
            y = ds[var].values if axis is None else ds[var].values[:, axis]
            points = ax.scatter(x[ok], y[ok], s=12, c=colours[ok] if numeric_colours else None, cmap="viridis")
            if numeric_colours and row == 0:
                fig.colorbar(points, ax=ax, label=colour_by)
            failed = ~ok & (ds["status"].values.astype(str) == "failed")
            if failed.any():
                ax.scatter(x[failed], np.full(failed.sum(), np.nanmean(y[ok]) if ok.any() else 0.0), marker="x",
                           color="red", label="failed")
                ax.legend(fontsize=7)
            ax.set_ylabel(label)
            ax.set_xlabel(name)
    if has_path:
        tip = int(ds.attrs["tip_mass"])
        z = ds["X"].sel(mass=tip, axis="z").values
        t = ds["time"].values
        members = np.flatnonzero(ok)[:200]
        for col, name in enumerate(names):
            ax = axes[-1, col]
            values = ds[name].values[members]
            numeric = np.issubdtype(np.asarray(values).dtype, np.number)
            span = (np.nanmin(values), np.nanmax(values)) if numeric and values.size else (0, 1)
            for m, v in zip(members, values):
                shade = (v - span[0]) / (span[1] - span[0]) if numeric and span[1] > span[0] else 0.5
                ax.plot(t, z[m], color=plt.cm.viridis(shade), lw=0.8)
            ax.set_xlabel("t [s]")
            ax.set_ylabel(f"tip z [m], coloured by {name}")
    fig.suptitle(f'{ds.attrs.get("scene_name")}: {ds.sizes["member"]} members, {ds.attrs.get("solver")}')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
