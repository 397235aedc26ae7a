"""Parametric scenes for the families users need: pendulums, chains and ropes, nets and cloth, closed
loops, rigid polyhedra, redundant trusses. Each returns a validated :class:`Scene` (``scene.save(path)``
writes its JSON)."""
from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from linknet_core.scene.description import Scene

G_EARTH = (0.0, 0.0, -9.81)


def _mass(name, position, mass=None, velocity=None, fixed=False):
    entry = {"name": name, "position": [float(v) for v in position]}
    if fixed:
        entry["fixed"] = True
    else:
        entry["mass"] = float(mass)
        if velocity is not None and np.any(np.asarray(velocity) != 0):
            entry["velocity"] = [float(v) for v in velocity]
    return entry


def pendulum(length=1.0, mass=1.0, angle_deg=90.0, gravity=G_EARTH, name="pendulum") -> Scene:
    """A point mass on a rigid rod from a pivot at the origin, released at rest ``angle_deg`` from the
    downward vertical (90: horizontal), in the x-z plane."""
    a = math.radians(angle_deg)
    bob = (length * math.sin(a), 0.0, -length * math.cos(a))
    return Scene.from_dict({
        "name": name, "description": f"simple pendulum, L = {length} m, released at rest {angle_deg} deg from vertical",
        "gravity": list(gravity),
        "masses": [_mass("pivot", (0, 0, 0), fixed=True), _mass("bob", bob, mass)],
        "links": [{"a": "pivot", "b": "bob", "length": length}]})


def chain(n_links: int, total_length=1.0, total_mass=1.0, shape="horizontal", anchor="start",
          gravity=G_EARTH, points: Sequence[Sequence[float]] | None = None, name=None,
          tip_mass: float | None = None, masses: Sequence[float] | None = None) -> Scene:
    """A chain (rope) of ``n_links`` equal rigid links with ``n_links + 1`` point masses.

    shape: 'horizontal' (released from the +x axis: a whipping chain), 'hanging' (straight down, static),
    or 'points' with ``points`` giving every mass position (any shape; lengths from the points).
    anchor: 'start' (mass 1 fixed), 'both' (first and last fixed), or 'none' (free rope).
    ``masses`` gives every free mass individually (mass ratios); ``tip_mass`` overrides the last one.
    """
    n = int(n_links)
    if n < 1:
        raise ValueError("a chain needs at least one link")
    h = total_length / n
    if shape == "horizontal":
        pos = np.column_stack([np.arange(n + 1) * h, np.zeros(n + 1), np.zeros(n + 1)])
    elif shape == "hanging":
        pos = np.column_stack([np.zeros(n + 1), np.zeros(n + 1), -np.arange(n + 1) * h])
    elif shape == "points":
        pos = np.asarray(points, float)
        if pos.shape != (n + 1, 3):
            raise ValueError(f"points must have shape ({n + 1}, 3)")
    else:
        raise ValueError(f"unknown chain shape {shape!r}")
    node_mass = np.full(n + 1, total_mass / (n + 1)) if masses is None else np.asarray(masses, float)
    if tip_mass is not None:
        node_mass = node_mass.copy()
        node_mass[-1] = tip_mass
    fixed = np.zeros(n + 1, bool)
    if anchor in ("start", "both"):
        fixed[0] = True
    if anchor == "both":
        fixed[-1] = True
    entries = [_mass(f"m{i}", pos[i], node_mass[i], fixed=fixed[i]) for i in range(n + 1)]
    links = [{"a": i + 1, "b": i + 2} if shape == "points" else {"a": i + 1, "b": i + 2, "length": h}
             for i in range(n)]
    return Scene.from_dict({"name": name or f"chain_{n}",
                            "description": f"chain of {n} rigid links, {shape}, anchor {anchor}",
                            "gravity": list(gravity), "masses": entries, "links": links})


def double_pendulum(l1=1.0, l2=1.0, m1=1.0, m2=1.0, gravity=G_EARTH, name="double_pendulum") -> Scene:
    """Two rods released from the horizontal (the issue's example scene)."""
    return Scene.from_dict({
        "name": name, "description": "double pendulum released from horizontal", "gravity": list(gravity),
        "masses": [_mass("pivot", (0, 0, 0), fixed=True), _mass("a", (l1, 0, 0), m1),
                   _mass("b", (l1 + l2, 0, 0), m2)],
        "links": [{"a": "pivot", "b": "a", "length": l1}, {"a": "a", "b": "b", "length": l2}]})


def _grid_links(n: int, m: int, diagonals: tuple[str, ...] = ()) -> list[dict]:
    """The links of an n x m grid of masses numbered row by row from 1, cell by cell in row order: to the right
    neighbour, to the one below, then the cell's diagonals named in ``diagonals`` ("down": (i, j)-(i+1, j+1),
    "up": (i, j+1)-(i+1, j)). Lengths are left to the positions."""
    idx = lambda i, j: i * m + j + 1  # noqa: E731
    ends = {"down": lambda i, j: (idx(i, j), idx(i + 1, j + 1)), "up": lambda i, j: (idx(i, j + 1), idx(i + 1, j))}
    links = []
    for i in range(n):
        for j in range(m):
            if j + 1 < m:
                links.append({"a": idx(i, j), "b": idx(i, j + 1)})
            if i + 1 < n:
                links.append({"a": idx(i, j), "b": idx(i + 1, j)})
            if i + 1 < n and j + 1 < m:
                for kind in diagonals:
                    a, b = ends[kind](i, j)
                    links.append({"a": a, "b": b})
    return links


def net(n: int, m: int, spacing=0.1, total_mass=1.0, anchors: str | Iterable[tuple[int, int]] = "opposite_corners",
        gravity=G_EARTH, name=None, diagonals=False) -> Scene:
    """An n x m net (cloth) of masses in the horizontal x-y plane, joined to their grid neighbours.

    anchors: 'opposite_corners' (first and last mass), 'corners' (the two corners of the first row: that
    row is then a taut string, a state of self-stress), 'four_corners', 'edge' (the whole first row), 'none',
    or a list of (i, j) grid indices. ``diagonals`` adds both diagonals of every cell (a
    redundant, shear-stiff cloth).
    """
    ii, jj = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    idx = lambda i, j: i * m + j  # noqa: E731
    if anchors == "opposite_corners":
        anchor_set = {(0, 0), (n - 1, m - 1)}
    elif anchors == "corners":
        anchor_set = {(0, 0), (0, m - 1)}
    elif anchors == "four_corners":
        anchor_set = {(0, 0), (0, m - 1), (n - 1, 0), (n - 1, m - 1)}
    elif anchors == "edge":
        anchor_set = {(0, j) for j in range(m)}
    elif anchors == "none":
        anchor_set = set()
    else:
        anchor_set = {tuple(a) for a in anchors}
    mass_each = total_mass / (n * m)
    entries = [_mass(f"n{i}_{j}", (j * spacing, i * spacing, 0.0), mass_each, fixed=(i, j) in anchor_set)
               for i in range(n) for j in range(m)]
    links = []
    for i in range(n):
        for j in range(m):
            if j + 1 < m:
                links.append({"a": idx(i, j) + 1, "b": idx(i, j + 1) + 1, "length": spacing})
            if i + 1 < n:
                links.append({"a": idx(i, j) + 1, "b": idx(i + 1, j) + 1, "length": spacing})
            if diagonals and i + 1 < n and j + 1 < m:
                d = spacing * math.sqrt(2.0)
                links.append({"a": idx(i, j) + 1, "b": idx(i + 1, j + 1) + 1, "length": d})
                links.append({"a": idx(i, j + 1) + 1, "b": idx(i + 1, j) + 1, "length": d})
    links = [l for l in links if not ((divmod(l["a"] - 1, m) in anchor_set) and (divmod(l["b"] - 1, m) in anchor_set))]
    return Scene.from_dict({"name": name or f"net_{n}x{m}",
                            "description": f"{n} x {m} net, spacing {spacing} m, anchors {anchors}",
                            "gravity": list(gravity), "masses": entries, "links": links})


def four_bar(ground=1.0, crank=0.3, coupler=1.0, rocker=0.6, crank_angle_deg=60.0, crank_speed=2.0,
             mass_b=1.0, mass_c=1.0, gravity=G_EARTH, name="four_bar") -> Scene:
    """Planar four-bar linkage in the x-z plane: pivots A (origin) and D (ground, 0, 0), crank A-B,
    coupler B-C, rocker C-D (a closed loop through the ground). The crank turns at ``crank_speed`` rad/s;
    the velocity of C is the consistent one (both constraints (12) hold exactly)."""
    th = math.radians(crank_angle_deg)
    A = np.zeros(3)
    D = np.array([ground, 0.0, 0.0])
    B = A + crank * np.array([math.cos(th), 0.0, math.sin(th)])
    # C: intersection of circle(B, coupler) and circle(D, rocker) in the x-z plane, upper branch
    d = np.linalg.norm(D - B)
    if d > coupler + rocker or d < abs(coupler - rocker):
        raise ValueError("these link lengths cannot close the loop at this crank angle")
    a = (coupler ** 2 - rocker ** 2 + d ** 2) / (2 * d)
    hgt = math.sqrt(max(coupler ** 2 - a ** 2, 0.0))
    e = (D - B) / d
    perp = np.array([-e[2], 0.0, e[0]])
    C = B + a * e + hgt * perp
    if C[2] < B[2] + a * e[2]:
        C = B + a * e - hgt * perp
    UB = crank_speed * crank * np.array([-math.sin(th), 0.0, math.cos(th)])
    # U_C in the plane with (U_C - U_B).(C - B) = 0 and U_C.(C - D) = 0
    M2 = np.array([[(C - B)[0], (C - B)[2]], [(C - D)[0], (C - D)[2]]])
    rhs = np.array([UB @ (C - B), 0.0])
    ucx, ucz = np.linalg.solve(M2, rhs)
    UC = np.array([ucx, 0.0, ucz])
    return Scene.from_dict({
        "name": name, "description": "planar four-bar linkage (closed loop through the ground)",
        "gravity": list(gravity),
        "masses": [_mass("A", A, fixed=True), _mass("B", B, mass_b, UB), _mass("C", C, mass_c, UC),
                   _mass("D", D, fixed=True)],
        "links": [{"a": "A", "b": "B"}, {"a": "B", "b": "C"}, {"a": "C", "b": "D"}]})


def tetrahedron(edge=1.0, mass=1.0, spin=(0.0, 0.0, 10.0), velocity=(0.0, 0.0, 0.0), gravity=(0.0, 0.0, 0.0),
                name="spinning_tetrahedron") -> Scene:
    """Regular tetrahedron of 4 masses and 6 links, centroid at the origin, apex on the +z axis, spinning
    with angular velocity ``spin`` (rad/s) about its centroid. About the z axis (a 3-fold axis through the
    apex) the base links carry T = M w^2 a / 3 and the side links none."""
    r = edge / math.sqrt(3.0)  # circumradius of the base triangle
    h = edge * math.sqrt(2.0 / 3.0)
    base = [np.array([r * math.cos(t), r * math.sin(t), 0.0]) for t in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)]
    apex = np.array([0.0, 0.0, h])
    pts = np.array(base + [apex])
    pts -= pts.mean(axis=0)
    w = np.asarray(spin, float)
    entries = [_mass(nm, p, mass, np.cross(w, p) + np.asarray(velocity, float))
               for nm, p in zip(("b1", "b2", "b3", "apex"), pts)]
    links = [{"a": a, "b": b} for a, b in (("b1", "b2"), ("b2", "b3"), ("b3", "b1"),
                                          ("b1", "apex"), ("b2", "apex"), ("b3", "apex"))]
    return Scene.from_dict({"name": name, "description": f"regular tetrahedron, edge {edge} m, spin {list(w)} rad/s",
                            "gravity": list(gravity), "masses": entries, "links": links})


def redundant_truss(bays=2, bay_length=1.0, mass=1.0, gravity=G_EARTH, name="redundant_truss") -> Scene:
    """A cantilevered triangular-prism truss: three anchors on the wall x = 0, then ``bays`` bays each
    with 3 longitudinal links, a triangle and both diagonals of its 3 side faces. 12 links per bay on 3
    masses (9 degrees of freedom): 3 states of self-stress per bay, so A of (25) is singular."""
    tri = [np.array([0.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.5, 0.8])]
    entries = [_mass(f"w{i}", p, fixed=True) for i, p in enumerate(tri)]
    links = []
    for b in range(1, bays + 1):
        for i, p in enumerate(tri):
            entries.append(_mass(f"n{b}_{i}", p + np.array([b * bay_length, 0.0, 0.0]), mass))
        prev = [f"w{i}" for i in range(3)] if b == 1 else [f"n{b - 1}_{i}" for i in range(3)]
        cur = [f"n{b}_{i}" for i in range(3)]
        for i in range(3):
            links.append({"a": prev[i], "b": cur[i]})  # longitudinal
            links.append({"a": cur[i], "b": cur[(i + 1) % 3]})  # triangle
            links.append({"a": prev[i], "b": cur[(i + 1) % 3]})  # both diagonals of the side face
            links.append({"a": prev[(i + 1) % 3], "b": cur[i]})
    return Scene.from_dict({"name": name, "description": f"cantilevered prism truss, {bays} bays, both diagonals per face",
                            "gravity": list(gravity), "masses": entries, "links": links})


def triangulated_net(n=6, m=6, spacing=0.1, total_mass=1.0, sag=0.3, gravity=G_EARTH, name="triangulated_net") -> Scene:
    """An n x m cloth with both diagonals in every cell, hung from the two corners of its first row, released
    at rest from a sagged shape: z = -sag (m-1) spacing 4u(1-u)(0.3 + v) (u along the first row, v across,
    both from 0 to 1). Lengths are those of that shape, so every cell is a non-planar quadrilateral whose six
    links make a rigid tetrahedron: the cloth has states of self-stress (redundant links) and a few mechanisms,
    and swings under gravity. (Released flat and horizontal, a cloth of rigid cells meets gravity
    perpendicular to every link: a singular configuration no integrator can leave.)"""
    anchors = {(0, 0), (0, m - 1)}
    entries = []
    for i in range(n):
        for j in range(m):
            u, v = j / (m - 1), i / (n - 1)
            z = -sag * spacing * (m - 1) * 4.0 * u * (1.0 - u) * (0.3 + v)
            entries.append(_mass(f"n{i}_{j}", (j * spacing, i * spacing, z), total_mass / (n * m - len(anchors)),
                                 fixed=(i, j) in anchors))
    links = _grid_links(n, m, ("down", "up"))
    return Scene.from_dict({"name": name, "description": f"{n} x {m} cloth with both diagonals per cell, sagged, "
                            "hung from two corners (states of self-stress and mechanisms)",
                            "gravity": list(gravity), "masses": entries, "links": links})


def braced_tower(width=1.0, storey=1.0, mass=1.0, tilt=(0.3, 0.0), name="braced_tower") -> Scene:
    """A two-storey tower on four anchors at the corners of a square: four posts per storey, a square at each
    floor, both diagonals in the top square (one state of self-stress) and no bracing on the sides, so both
    storeys sway (mechanisms). Gravity 9.81 m/s^2 tilted by ``tilt`` = (g_x, g_y) / g sets it swaying from rest."""
    gx, gy = tilt
    g = 9.81
    gravity = [g * gx, g * gy, -g * math.sqrt(1.0 - gx * gx - gy * gy)]
    corners = [(0.0, 0.0), (width, 0.0), (width, width), (0.0, width)]
    entries = [_mass(f"a{c}", (x, y, 0.0), fixed=True) for c, (x, y) in enumerate(corners)]
    for level in (1, 2):
        entries += [_mass(f"s{level}_{c}", (x, y, level * storey), mass) for c, (x, y) in enumerate(corners)]
    links = []
    for level in (1, 2):
        below = [f"a{c}" if level == 1 else f"s1_{c}" for c in range(4)]
        floor = [f"s{level}_{c}" for c in range(4)]
        for c in range(4):
            links.append({"a": below[c], "b": floor[c]})
            links.append({"a": floor[c], "b": floor[(c + 1) % 4]})
    links += [{"a": "s2_0", "b": "s2_2"}, {"a": "s2_1", "b": "s2_3"}]
    return Scene.from_dict({"name": name, "description": "two-storey tower on four anchors, both diagonals in the "
                            "top square (one self-stress), unbraced sides (mechanisms), gravity tilted",
                            "gravity": gravity, "masses": entries, "links": links})


def taut_string(speed=1.0, mass=1.0, name="taut_string") -> Scene:
    """A mass between two anchors on two collinear links (a taut string), moving sideways at ``speed``.

    The velocity satisfies (12), yet admits no consistent accelerations (35): the self-stress T1 = T2 is
    not orthogonal to |dU|^2/R. This is the seed's acknowledgment case; loading it must fail (speed != 0).
    """
    return Scene.from_dict({
        "name": name, "description": "taut string: violates hypothesis (35) when the middle mass moves sideways",
        "masses": [_mass("left", (0, 0, 0), fixed=True), _mass("middle", (1, 0, 0), mass, (0, speed, 0)),
                   _mass("right", (2, 0, 0), fixed=True)],
        "links": [{"a": "left", "b": "middle"}, {"a": "middle", "b": "right"}]})


def crane(n_links=5, rope_length=2.0, load=10.0, rope_mass=1.0, travel=3.0, travel_time=3.0,
          gravity=G_EARTH, name="crane") -> Scene:
    """A trolley crane: a rope of ``n_links`` links hanging from a driven anchor (the trolley) with a load at its
    end. The trolley travels ``travel`` m along x in ``travel_time`` s on a clamped spline (starting and stopping
    at rest) and then stands: the load swings behind and after it."""
    n = int(n_links)
    h = rope_length / n
    node = np.full(n + 1, rope_mass / n)
    node[-1] = load
    masses = [{"name": "trolley", "position": [0.0, 0.0, 0.0], "driven": True,
               "motion": {"kind": "waypoints", "waypoints": [[travel_time, travel, 0.0, 0.0]]}}]
    masses += [_mass(f"rope{i}" if i < n else "load", (0.0, 0.0, -i * h), node[i]) for i in range(1, n + 1)]
    return Scene.from_dict({
        "name": name, "description": f"trolley crane: {n}-link rope of {rope_length} m, {load} kg load, the trolley "
                                     f"travels {travel} m in {travel_time} s (clamped spline) and stops",
        "gravity": list(gravity), "masses": masses,
        "links": [{"a": i + 1, "b": i + 2, "length": h} for i in range(n)]})


def triangulated_net_corners(n=4, spacing=0.1, total_mass=1.0, fold=0.0, gravity=G_EARTH,
                             name="triangulated_net_4x4_corners") -> Scene:
    """An n x n net with one diagonal per cell, all parallel to the diagonal from mass n0_0 to mass n{n-1}_{n-1},
    hung from those two opposite corners, released at rest. The diagonal links between the anchors lie on one
    straight line: a taut string whose inner masses are held at second order only (a self-stress with a flex
    across it). The two triangulated halves hang folded below the string, at z = -fold spacing (i - j)^2 / (n - 1)
    (i, j the row and column): curved, so the only flat, loaded place is the string. Lengths are those of that
    shape. Gravity pulls the string's inner masses across it, so the rigid links have no bounded tensions there."""
    anchors = {(0, 0), (n - 1, n - 1)}
    entries = []
    for i in range(n):
        for j in range(n):
            z = -fold * spacing * (i - j) ** 2 / (n - 1)
            entries.append(_mass(f"n{i}_{j}", (j * spacing, i * spacing, z), total_mass / (n * n - len(anchors)),
                                 fixed=(i, j) in anchors))
    links = _grid_links(n, n, ("down",))
    return Scene.from_dict({"name": name, "description": f"{n} x {n} net with one diagonal per cell, hung from two "
                            "opposite corners: the diagonal links between them are a taut straight string (second-"
                            "order rigid), the halves folded below it", "gravity": list(gravity),
                            "masses": entries, "links": links})


def tilted_tower(width=1.0, storey=1.0, mass=1.0, tilt=(0.3, 0.2), braced_faces=(0, 1), name="tilted_tower") -> Scene:
    """braced_tower with one diagonal brace in ``braced_faces`` of the first storey's four side faces (face c joins
    corners c and c+1), gravity tilted by ``tilt`` = (g_x, g_y) / g. The braces stiffen the first storey against
    sway in their planes, so the tilted load twists it while the top storey sways, and the storey below twists the
    flat braced top square: rigid links hold that twist only at second order, with tensions that grow without bound
    (benchmarks.degenerate_limit: with springs, the square's stretch stays 3.3e-8 at every stiffness)."""
    gx, gy = tilt
    g = 9.81
    gravity = [g * gx, g * gy, -g * math.sqrt(1.0 - gx * gx - gy * gy)]
    tower = braced_tower(width, storey, mass, tilt).to_dict()
    tower["links"] += [{"a": f"a{c}", "b": f"s1_{(c + 1) % 4}"} for c in braced_faces]
    tower.update(name=name, gravity=gravity, description="two-storey tower on four anchors, first storey braced on "
                 f"faces {list(braced_faces)}, both diagonals in the top square, gravity tilted")
    return Scene.from_dict(tower)


def braced_panel_net(n=4, spacing=0.1, total_mass=1.0, fold_deg=60.0, tilt_deg=30.0, spin=(1.0, 2.0, 3.0),
                     gravity=G_EARTH, name="braced_panel_net") -> Scene:
    """An n x n net with both diagonals in every cell (each cell a flat doubly braced square: a self-stress and a
    first-order twist out of its plane that is no finite motion, (27)), pinned at its corner n0_0, folded by
    ``fold_deg`` along the grid line x = spacing, the whole turned by ``tilt_deg`` about the x axis and spinning
    rigidly about the pin at ``spin`` (rad/s). The minimum-norm tensions give the cells' twists no resistance
    (hypothesis (35) fails along them as soon as a velocity acquires one); the same net with stiff springs does not
    converge as the stiffness grows (benchmarks.degenerate_limit), so the rigid model has no bounded-tension motion."""
    a, t = math.radians(fold_deg), math.radians(tilt_deg)
    pts = []
    for i in range(n):
        for j in range(n):
            x, y = j * spacing, i * spacing
            if x > spacing:  # the part beyond the fold line turned up by the fold angle about it
                r = x - spacing
                x, z = spacing + r * math.cos(a), r * math.sin(a)
            else:
                z = 0.0
            pts.append((x, y, z))
    rot = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(t), -math.sin(t)], [0.0, math.sin(t), math.cos(t)]])
    pts = np.asarray(pts) @ rot.T
    w = np.asarray(spin, float)
    vel = np.cross(w, pts - pts[0])
    entries = [_mass(f"n{i}_{j}", pts[i * n + j], total_mass / (n * n - 1), vel[i * n + j], fixed=(i, j) == (0, 0))
               for i in range(n) for j in range(n)]
    links = _grid_links(n, n, ("down", "up"))
    return Scene.from_dict({"name": name, "description": f"{n} x {n} net of flat doubly braced cells (second-order "
                            f"rigid), pinned at a corner, folded {fold_deg} deg, tilted {tilt_deg} deg, spinning",
                            "gravity": list(gravity), "masses": entries, "links": links})


def shipped_scenes() -> dict[str, Scene]:
    """The scenes in models/ (regenerate with ``python models/generate.py``)."""
    return {
        "pendulum": pendulum(),
        "double_pendulum": double_pendulum(),
        "chain_10": chain(10),
        "chain_100": chain(100),
        "four_bar": four_bar(),
        "spinning_tetrahedron": tetrahedron(),
        "redundant_truss": redundant_truss(),
        "net_10x10": net(10, 10),
        "crane": crane(),
        "triangulated_net": triangulated_net(),
        "braced_tower": braced_tower(),
    }


def degenerate_scenes() -> dict[str, Scene]:
    """The scenes in models/degenerate/: nets that people build whose rigid parts are rigid only at second order
    (a taut straight string between anchors, flat doubly braced panels) or that reach a configuration where the
    constraint Jacobian loses rank. The point-mass methods do not carry them through yet (docs/robust_stepping.md):
    they are kept apart from the shipped scenes, which run to their stop time with every method."""
    return {
        "triangulated_net_4x4_corners": triangulated_net_corners(),
        "tilted_tower": tilted_tower(),
        "braced_panel_net": braced_panel_net(),
    }
