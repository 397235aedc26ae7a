"""Jumps of a driven anchor's position, as the FMUs say them. The native FMU says them in the same words
(fmu_src/native/linknet_model.c, position_jump_items and the texts beside it); tests compare the two.

An input-driven anchor's P, V, A are held as P + V tau + A tau^2/2 from the communication point where they were set.
Inputs set at t whose P is not where the held motion had the anchor at t make a position jump there, and so does a
V or A set without P, since the motion restarts from the P last set. The core takes a position jump
(linknet_core/dynamics/drive.py anchor_jump, native drive.c ln_drive_jump) as a relocation: the anchor is put at P,
the free masses are projected onto the link lengths (11) in the mass metric and their velocities onto (12) relative
to the anchor's new V, and the impulse of that velocity projection is reported (in Jreact, which adds the impulses of
the rope and ground events in the step), none for the displacement itself, which made in no time would take an
unbounded impulse. The FMUs say so, naming the inputs, with the projection's impulse.
"""
from __future__ import annotations

import numpy as np

# A coordinate's jump counts when it exceeds ROUND_OFF * (|P| + the shortest link at the anchor): inputs that continue
# the held motion (a master following a smooth motion, or the held quadratic's own values) meet it to round-off.
ROUND_OFF = 1e-12
# A jump longer than this fraction of the shortest link at the anchor is logged every time; shorter ones (a master
# whose inputs do not quite continue the held motion, at every step) once per instance.
LOGGED_ALWAYS = 1e-3
MAX_LISTED = 6  # coordinates named in one message

RELOCATION = ("A jump of position is no motion the links can follow (made in no time it would take an unbounded "
              "impulse), so it was taken as a relocation: the anchor was put there, the free masses were moved to the "
              "nearest positions (in the mass metric) that keep the link lengths, and their velocities were projected "
              "onto the links relative to the anchor's velocity; the impulse of that projection is in Jreact (with "
              "those of the rope and ground events later in the step), none is counted for the displacement; the "
              "projection's: ")
RULE = ("a driven anchor's position input must continue its held motion P + V tau + A tau^2/2: a jump is taken by "
        "moving the free masses onto the link lengths at once, which fails where the links cannot follow it; move the "
        "anchor there over several steps (set P, V and A together, or give V and A as P's input derivatives)")


def shortest_links(k1, k2, length, anchors) -> np.ndarray:
    """The shortest link at each anchor (mass indices `anchors`), inf for an anchor without links."""
    k1, k2, length = np.asarray(k1), np.asarray(k2), np.asarray(length, float)
    out = np.full(len(anchors), np.inf)
    for j, k in enumerate(anchors):
        at = (k1 == k) | (k2 == k)
        if at.any():
            out[j] = length[at].min()
    return out


def jumps(P, X, shortest):
    """(counted, long): (n, 3) masks of the coordinates whose jump from X (where the held motion had the anchors) to P
    (the inputs set) counts, and of those longer than LOGGED_ALWAYS of the shortest link at their anchor."""
    d = np.abs(P - X)
    reach = np.asarray(shortest, float)[:, None]
    counted = d > ROUND_OFF * (np.abs(P) + reach)
    return counted, counted & (d > LOGGED_ALWAYS * reach)


def items(names, vrs, P, X, mask) -> str:
    """The jumped coordinates: each input's name, value reference, value, where the held motion had it and the jump."""
    where = np.argwhere(mask)
    out = [f"{names[j][i]} (valueReference {vrs[j][i]}) = {P[j, i]:g} m where the held motion had the anchor at "
           f"{X[j, i]:g} m (a jump of {abs(P[j, i] - X[j, i]):g} m)" for j, i in where[:MAX_LISTED]]
    if len(where) > MAX_LISTED:
        out.append(f"and {len(where) - MAX_LISTED} more")
    return "; ".join(out)


def impulses(names, J, anchors) -> str:
    """The jump's impulses on the anchors (rows of J, (n, 3)), by their Jreact names."""
    return ", ".join(f"{names[j][i]} = {J[j, i]:g}" for j in anchors for i in range(3))


def position_jump_warning(t, listed, impulse, first_short=None) -> str:
    """A jump of P (first_short: the length below which jumps are logged once per instance, where this is that
    once)."""
    once = "" if first_short is None else (
        f" Jumps shorter than a thousandth of the shortest link at the anchor ({first_short:g} m here) are logged "
        "once per instance, this one; longer ones every time.")
    return (f"position jump at t={t:g}: {listed}. {RELOCATION}{impulse} N s. For a motion, set P, V and A together so "
            f"that P continues the held motion P + V tau + A tau^2/2 (or give V and A as P's input derivatives).{once}")


def set_without_p_warning(t, name, vr, listed, impulse) -> str:
    """V or A set without P (said once per instance)."""
    return (f"{name} (valueReference {vr}) was set at t={t:g} without P of its anchor, so the held motion P + V tau + "
            f"A tau^2/2 restarted from the P last set: {listed}. This happens at every step where V or A is set "
            f"without P, and is logged once per instance. {RELOCATION}{impulse} N s. Set P with V and A so that P "
            "continues the held motion (or give V and A as P's input derivatives).")


def failure_note(listed) -> str:
    """Added to the reason of a step that began with a position jump and failed."""
    return f". The step began with a position jump: {listed}; {RULE}"
