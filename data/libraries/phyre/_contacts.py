"""Prelude: contact episodes of object pairs from the `contact_begin` / `contact_end` events, a pair's
contact that begins again within MERGE_S (50 ms) of its end being the same contact (a bouncing or
rocking body chatters). Without an event log, contacts come from geometry: two bodies whose outlines are
at most CONTACT_GAP px apart touch (DENSE_GAP when the frames hold every 60 Hz physics step; bodies
that never move do not touch each other). Outlines are rebuilt from what every PHYRE trace carries (shape,
diameter, position of the body origin, angle): a ball is a circle; a bar a 5.12 px thick rectangle
whose diagonal is the diameter; a jar PHYRE's cup of three convex pieces (a base 0.533 D wide and two
slanted walls up to 0.8 D, wall thickness 3.824 + 1.179 ln(D / 32) px, as PHYRE builds them); the four
walls bound the 256 px scene, as objects of shape `wall` when the trace lists them, else as implicit
walls "-4" (floor), "-3" (left), "-2" (ceiling), "-1" (right): PHYRE's body indices 0-3 less 4, the
numbering of exported traces that omit the walls.

library.toml prepends it to the detectors that list it; it defines no find_pattern."""

CONTACT_GAP = 1.5
DENSE_GAP = 0.15
SCENE = 256.0
BAR_THICKNESS = 5.12


def _poly_world(o, pts):
    x, y, a = float(o.get("x", 0.0)), float(o.get("y", 0.0)), float(o.get("angle", 0.0) or 0.0)
    c, s = _cos(a), _sin(a)
    return [(x + c * px - s * py, y + s * px + c * py) for px, py in pts]


def _sin(a):
    """sin by its Taylor series after range reduction (detectors cannot import math)."""
    pi = 3.141592653589793
    a = (a + pi) % (2 * pi) - pi
    term, total, n = a, a, 1
    while abs(term) > 1e-15:
        term *= -a * a / ((n + 1) * (n + 2))
        total += term
        n += 2
    return total


def _cos(a):
    return _sin(a + 1.5707963267948966)


def _ln(x):
    """Natural logarithm (no math module): ln x = 2 atanh((x-1)/(x+1)) after halving into [0.5, 1]."""
    k = 0
    while x > 1.0:
        x /= 2.0
        k += 1
    z = (x - 1.0) / (x + 1.0)
    term, total, n = z, 0.0, 1
    while abs(term) > 1e-17:
        total += term / n
        term *= z * z
        n += 2
    return 2.0 * total + k * 0.6931471805599453


def _outline(o):
    """("circle", cx, cy, r) or ("polys", [convex polygons in scene px]) of a trace object."""
    shape = o.get("shape")
    d = float(o.get("diameter", 0.0))
    if shape == "ball" or d <= 0.0:
        return ("circle", float(o.get("x", 0.0)), float(o.get("y", 0.0)), d / 2.0)
    if shape == "jar":
        t = 3.8243 + 1.1794 * _ln(d / 32.0)
        hb, top = 0.26667 * d, 0.8 * d - t / 2.0
        polys = [[(hb, t / 2.0), (-hb, t / 2.0), (-hb, -t / 2.0), (hb, -t / 2.0)]]
        for sgn in (-1.0, 1.0):
            bx, by, tx, ty = sgn * hb, -t / 2.0, sgn * d / 3.0, top
            ux, uy = tx - bx, ty - by
            n = (ux * ux + uy * uy) ** 0.5
            nx, ny = -sgn * uy / n * t, sgn * ux / n * t  # towards the inside of the jar
            if nx * sgn > 0:
                nx, ny = -nx, -ny
            ix, iy = bx + nx, by + ny  # inner bottom corner; the inner edge is cut level with the top
            jx = ix + ux * (ty - iy) / uy
            polys.append([(bx, by), (tx, ty), (jx, ty), (ix, iy)])
        return ("polys", [_poly_world(o, p) for p in polys])
    # bars (and any other shape: the diameter's rectangle)
    half_l = max(d * d - BAR_THICKNESS * BAR_THICKNESS, 0.0) ** 0.5 / 2.0
    h = BAR_THICKNESS / 2.0
    return ("polys", [_poly_world(o, [(half_l, h), (-half_l, h), (-half_l, -h), (half_l, -h)])])


def _implicit_walls(trace):
    """The scene's walls as half-planes when the trace does not list them (exported PHYRE traces)."""
    steps = trace.get("timesteps") or ()
    if steps and any(o.get("shape") == "wall" for o in steps[0].get("objects", [])):
        return []
    return [("-4", ("wall", 1, 0.0)), ("-3", ("wall", 0, 0.0)), ("-2", ("wall", 1, SCENE)),
            ("-1", ("wall", 0, SCENE))]


_IMPLICIT_CENTRES = {"-4": (128.0, -2.5), "-3": (-2.5, 128.0), "-2": (128.0, 258.5), "-1": (258.5, 128.0)}


def _body_at(trace, k, oid):
    """The object dict of body `oid` in timestep k, or for an implicit wall (a trace that omits the
    walls) a wall object at PHYRE's wall centre, so rules that compare positions see the floor below
    and the sides beside every body. None when there is no such body."""
    o = _obj_at(trace, k, oid)
    if o is None and oid in _IMPLICIT_CENTRES and _implicit_walls(trace):
        x, y = _IMPLICIT_CENTRES[oid]
        return {"object_index": int(oid), "shape": "wall", "x": x, "y": y, "diameter": 256.0}
    return o


def _wall_of(o):
    """A listed wall object as a half-plane boundary (axis, coordinate)."""
    wx, wy = float(o["x"]), float(o["y"])
    if wy < 0.0:
        return ("wall", 1, 0.0)
    if wy > SCENE:
        return ("wall", 1, SCENE)
    return ("wall", 0, 0.0) if wx < 0.0 else ("wall", 0, SCENE)


def _seg_dist(px, py, ax, ay, bx, by):
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    u = 0.0 if l2 <= 0.0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / l2))
    qx, qy = ax + u * dx - px, ay + u * dy - py
    return (qx * qx + qy * qy) ** 0.5


def _inside(px, py, poly):
    """Point inside a convex polygon (either winding)."""
    return _inside_e(px, py, _edges(poly))


def _poly_dist(p, q):
    """Distance between two convex polygons, 0 when they overlap."""
    if any(_inside(x, y, q) for x, y in p) or any(_inside(x, y, p) for x, y in q):
        return 0.0
    best = None
    for a, b in ((p, q), (q, p)):
        n = len(b)
        for x, y in a:
            for i in range(n):
                d = _seg_dist(x, y, b[i][0], b[i][1], b[(i + 1) % n][0], b[(i + 1) % n][1])
                if best is None or d < best:
                    best = d
    # Crossing edges without a vertex inside: overlapping.
    return best


def _circle_poly(cx, cy, r, poly):
    if _inside(cx, cy, poly):
        return -r
    n = len(poly)
    return min(_seg_dist(cx, cy, poly[i][0], poly[i][1], poly[(i + 1) % n][0], poly[(i + 1) % n][1])
               for i in range(n)) - r


def _extent(sh, axis):
    """(min, max) of an outline along x (axis 0) or y (axis 1)."""
    if sh[0] == "circle":
        c = sh[1 + axis]
        return c - sh[3], c + sh[3]
    vals = [p[axis] for poly in sh[1] for p in poly]
    return min(vals), max(vals)


def _gap(sa, sb):
    """Gap (px) between two outlines; negative or 0 when they overlap."""
    if sa[0] == "wall":
        sa, sb = sb, sa
    if sb[0] == "wall":
        lo, hi = _extent(sa, sb[1])
        return lo - sb[2] if sb[2] <= 0.0 else sb[2] - hi
    if sa[0] == "circle" and sb[0] == "circle":
        d = ((sa[1] - sb[1]) ** 2 + (sa[2] - sb[2]) ** 2) ** 0.5
        return d - sa[3] - sb[3]
    if sa[0] == "polys":
        sa, sb = sb, sa
    # Cheap reject on bounding boxes.
    for axis in (0, 1):
        a0, a1 = _extent(sa, axis)
        b0, b1 = _extent(sb, axis)
        if a0 - b1 > CONTACT_GAP or b0 - a1 > CONTACT_GAP:
            return CONTACT_GAP + 1.0
    if sa[0] == "circle":
        return min(_circle_poly(sa[1], sa[2], sa[3], q) for q in sb[1])
    return min(_poly_dist(p, q) for p in sa[1] for q in sb[1])


def _edges(poly):
    """A polygon's edges as (ax, ay, dx, dy, dx^2 + dy^2): the terms _seg_dist and _inside compute from
    an edge, computed once per outline instead of once per point tested against it."""
    n = len(poly)
    out = []
    for i in range(n):
        ax, ay = poly[i]
        bx, by = poly[(i + 1) % n]
        dx, dy = bx - ax, by - ay
        out.append((ax, ay, dx, dy, dx * dx + dy * dy))
    return out


def _inside_e(px, py, edges):
    """_inside over a polygon's _edges."""
    sign = 0
    for ax, ay, dx, dy, _ in edges:
        c = dx * (py - ay) - dy * (px - ax)
        if c != 0.0:
            s = 1 if c > 0 else -1
            if sign == 0:
                sign = s
            elif s != sign:
                return False
    return True


def _near_e(px, py, edges):
    """The least _seg_dist from a point to a polygon's _edges (the first of equals, as min keeps)."""
    best = None
    for ax, ay, dx, dy, l2 in edges:
        if l2 <= 0.0:
            u = 0.0
        else:
            u = ((px - ax) * dx + (py - ay) * dy) / l2
            u = u if u < 1.0 else 1.0  # min(1.0, u)
            u = u if u > 0.0 else 0.0  # max(0.0, u)
        qx, qy = ax + u * dx - px, ay + u * dy - py
        d = (qx * qx + qy * qy) ** 0.5
        if best is None or d < best:
            best = d
    return best


def _outline_gap(ea, eb):
    """_gap of two entries of _contacts' step list (oid, outline, is circle, extents, edges) whose
    outlines are not both circles and whose extents lie within CONTACT_GAP: the same arithmetic in the
    same order, over edges kept with the outline."""
    if not ea[2]:
        ea, eb = eb, ea  # a circle first, as _gap puts it
    if eb[4] is None:
        eb[4] = [_edges(q) for q in eb[1][1]]
    best = None
    if ea[2]:
        cx, cy, r = ea[1][1], ea[1][2], ea[1][3]
        for qe in eb[4]:
            d = -r if _inside_e(cx, cy, qe) else _near_e(cx, cy, qe) - r
            if best is None or d < best:
                best = d
        return best
    if ea[4] is None:
        ea[4] = [_edges(p) for p in ea[1][1]]
    for p, pe in zip(ea[1][1], ea[4]):
        for q, qe in zip(eb[1][1], eb[4]):
            if any(_inside_e(x, y, qe) for x, y in p) or any(_inside_e(x, y, pe) for x, y in q):
                d = 0.0
            else:
                d = None
                for pts, es in ((p, qe), (q, pe)):
                    for x, y in pts:
                        e = _near_e(x, y, es)
                        if d is None or e < d:
                            d = e
            if best is None or d < best:
                best = d
    return best


def _touching(shapes, moved, tol, pairs):
    """(a, b, gap) of each pair in a step's list of entries (oid, outline, is circle, extents, edges)
    with a body that moves, gap at most tol, in the list's order: _gap's values, with the extents at
    hand. A pair of outlines whose extents lie more than CONTACT_GAP apart on an axis is exactly a
    pair _gap answers CONTACT_GAP + 1 for without looking further; `pairs` keeps each pair's last
    measured gap of two outlines, used again while neither changes."""
    touching = []
    mv = [j for j, e in enumerate(shapes) if e[0] in moved]
    for i, ea in enumerate(shapes if mv else ()):
        a, sa, ca, ba, _ = ea
        for eb in shapes[i + 1:] if a in moved else [shapes[j] for j in mv if j > i]:
            b, sb, cb, bb, _ = eb
            # What _gap computes, with the extents at hand (walls have none).
            if ba is not None and bb is not None:
                if ca and cb:
                    gap = ((sa[1] - sb[1]) ** 2 + (sa[2] - sb[2]) ** 2) ** 0.5 - sa[3] - sb[3]
                elif (ba[0] - bb[1] > CONTACT_GAP or bb[0] - ba[1] > CONTACT_GAP
                      or ba[2] - bb[3] > CONTACT_GAP or bb[2] - ba[3] > CONTACT_GAP):
                    continue
                else:
                    c = pairs.get((a, b))
                    if c is not None and c[0] is ea and c[1] is eb:
                        gap = c[2]  # neither outline changed since this pair was last measured
                    else:
                        gap = _outline_gap(ea, eb)
                        pairs[(a, b)] = (ea, eb, gap)
            elif ba is not None and sb[0] == "wall":
                w = sb[2]
                gap = ba[2 * sb[1]] - w if w <= 0.0 else w - ba[2 * sb[1] + 1]
            elif bb is not None and sa[0] == "wall":
                w = sa[2]
                gap = bb[2 * sa[1]] - w if w <= 0.0 else w - bb[2 * sa[1] + 1]
            else:
                gap = _gap(sa, sb)
            if gap <= tol:
                touching.append((a, b, gap))
    return touching


def _contacts(trace):
    """Contact episodes in time order: {pair, t0, t1, begins, ended} (from geometry also t_seen: the
    contact began between t0 and t_seen)."""
    idx, ts = _clock(trace)
    if not ts:
        return []
    groups, out = {}, []
    evs = []
    for e in trace.get("events", []):
        if e.get("kind") in ("contact_begin", "contact_end") and e.get("t") is not None:
            evs.append((float(e["t"]), e["kind"], e.get("payload") or {}))
    if evs:
        evs.sort(key=lambda x: x[0])
        for t, kind, p in evs:
            ag = [str(x) for x in (p.get("agents") or p.get("objects") or [])][:2]
            if len(ag) != 2:
                continue
            key = tuple(sorted(ag))
            g = groups.get(key)
            if kind == "contact_end":
                if g is not None:
                    g["t1"], g["ended"] = t, True
                continue
            if t > ts[-1] + 1e-9:
                continue  # after the last frame: no span can hold it
            if g is not None and (not g["ended"] or t - g["t1"] <= MERGE_S):
                g["begins"].append(t)
                g["ended"], g["t1"] = False, ts[-1]
                continue
            g = {"pair": key, "t0": t, "t1": ts[-1], "begins": [t], "ended": False}
            groups[key] = g
            out.append(g)
        return out
    walls = _implicit_walls(trace)
    steps = trace["timesteps"]
    # Frames at every 60 Hz physics step show a contact as it happens: Box2D keeps touching outlines
    # within DENSE_GAP. Sparser frames need the slack of CONTACT_GAP (the contact fell between them).
    gaps = sorted(ts[i + 1] - ts[i] for i in range(len(ts) - 1))
    dense = bool(gaps) and gaps[len(gaps) // 2] <= 1.0 / 60.0 + 1e-6
    tol = DENSE_GAP if dense else CONTACT_GAP
    # Bodies that never move (static bars, walls; float32 noise aside) do not collide with each other.
    first = {}
    moved = set()
    seen = {}  # object id -> the dict last looked at: a step that repeats it (same dict) changes nothing
    for s in steps:
        for o in s.get("objects", []):
            oid = str(o.get("object_index"))
            if oid in moved or seen.get(oid) is o or o.get("shape") == "wall":
                continue
            seen[oid] = o
            p = (float(o.get("x", 0.0)), float(o.get("y", 0.0)), float(o.get("angle", 0.0) or 0.0))
            q = first.setdefault(oid, p)
            if abs(p[0] - q[0]) + abs(p[1] - q[1]) > 0.01 or abs(p[2] - q[2]) > 1e-4:
                moved.add(oid)
    # A body whose shape, size, position and angle equal its previous step's keeps that step's entry
    # (outline, extents, edges): static bodies, and bodies at rest, every step. A step whose entries
    # are all the previous step's has its touching pairs.
    last, listed, pairs = {}, {}, {}
    wall_entries = [(a, sh, False, None, None) for a, sh in walls]
    before, touching = None, []
    for k, s in enumerate(steps):
        shapes = []
        for o in s.get("objects", []):
            oid = str(o["object_index"])
            if o.get("shape") == "wall":
                w = listed.get(oid)
                if w is None or w[1] is not o:
                    w = ((oid, _wall_of(o), False, None, None), o)
                    listed[oid] = w
                shapes.append(w[0])
                continue
            prev = last.get(oid)
            if prev is not None and prev[2] is o:
                shapes.append(prev[1])
                continue
            key = (o.get("shape"), o.get("diameter", 0.0), o.get("x", 0.0), o.get("y", 0.0),
                   o.get("angle", 0.0))
            if prev is not None and prev[0] == key:
                last[oid] = (key, prev[1], o)
                shapes.append(prev[1])
                continue
            sh = _outline(o)
            entry = [oid, sh, sh[0] == "circle", _extent(sh, 0) + _extent(sh, 1), None]
            last[oid] = (key, entry, o)
            shapes.append(entry)
        shapes += wall_entries
        if before is None or len(shapes) != len(before) or any(x is not y for x, y in zip(shapes, before)):
            touching = _touching(shapes, moved, tol, pairs)
        before = shapes
        for a, b, gap in touching:
            key = tuple(sorted((a, b)))
            g = groups.get(key)
            if g is not None and (g["last_k"] == k - 1 or ts[k] - g["t1"] <= MERGE_S):
                g["t1"], g["last_k"] = ts[k], k
                continue
            # The contact began after the previous frame: by this frame when the bodies already press
            # together, else (a gap of up to CONTACT_GAP) possibly only before the next one.
            t0 = ts[k - 1] if k > 0 else ts[0]
            t_seen = ts[k] if gap <= 0.0 or dense or k + 1 >= len(ts) else ts[k + 1]
            g = {"pair": key, "t0": t0, "t_seen": t_seen, "t1": ts[k], "begins": [t0], "ended": True,
                 "last_k": k}
            groups[key] = g
            out.append(g)
    out.sort(key=lambda g: g["t0"])
    return out


def _in_contact(contacts, oid, t):
    return [g for g in contacts if oid in g["pair"] and g["t0"] - 1e-9 <= t <= g["t1"] + 1e-9]
