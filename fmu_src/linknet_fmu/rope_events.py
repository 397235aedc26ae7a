"""The rope and ground events of a doStep as the FMU reports them: the impulses summed per rope and per mass
(outputs Jrope[l], Jground[k]) and one log message per event."""
from __future__ import annotations

import numpy as np

# the kinds whose index is a link (the others' is a mass)
LINK_KINDS = ("taut", "slack")


def event_impulses(events, rope_links, ground_masses):
    """(per rope link of ``rope_links``, per mass of ``ground_masses``): the impulses (N s) of the events, summed:
    a rope's taut events, a mass's contact events (the ground's normal impulse)."""
    rope_row = {int(l): j for j, l in enumerate(rope_links)}
    mass_row = {int(k): j for j, k in enumerate(ground_masses)}
    J_rope, J_ground = np.zeros(len(rope_links)), np.zeros(len(ground_masses))
    for event in events:
        if event.kind == "taut":
            J_rope[rope_row[event.index]] += event.impulse
        elif event.kind == "contact":
            J_ground[mass_row[event.index]] += event.impulse
    return J_rope, J_ground


def event_message(event, scene) -> str:
    """One event in words: its time, kind, link or mass (1-based, named) and impulse."""
    what = scene.link_label(event.index) if event.kind in LINK_KINDS else scene.mass_label(event.index)
    return f"event at t={event.t!r}: {event.kind} of {what}, impulse {event.impulse:.17g} N s"
