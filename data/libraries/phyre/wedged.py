"""wedged: a dynamic body is held still between two or more others: at rest (at most REST_V px/s and
ROT_V rad/s) for at least MIN_S while touching at least two bodies that press from opposing sides (the
directions from it towards two of them at least OPPOSED_DEG = 120 degrees apart; a wall's direction is
straight at it, a ball's towards its centre, a bar's or jar's towards the point of its outline nearest
to the body's centre, where it pushes — not its centre, which for a long bar under a ball lies off to the
side) and from opposite sides horizontally (each
direction's horizontal part at least SIDE of its length, opposite in sign). So a ball on the floor beside
another ball (90 degrees) and a stack (pressed only from above and below) are not wedged; jars, which
hold things, are never the wedged body."""

REST_V = 2.0
ROT_V = 0.1
MIN_S = 0.5
OPPOSED_COS = -0.5  # cos(120 degrees)
SIDE = 0.3


def _towards(o, p):
    """Unit direction from body o towards body p (walls: straight at the wall)."""
    px, py = float(p["x"]), float(p["y"])
    if p.get("shape") == "wall":
        if py < 0.0:
            return (0.0, -1.0)
        if py > 256.0:
            return (0.0, 1.0)
        return (-1.0, 0.0) if px < 0.0 else (1.0, 0.0)
    ox, oy = float(o["x"]), float(o["y"])
    sh = _outline(p)
    if sh[0] == "polys" and not any(_inside(ox, oy, poly) for poly in sh[1]):
        best = None
        for poly in sh[1]:
            n = len(poly)
            for i in range(n):
                q = _seg_near(ox, oy, poly[i], poly[(i + 1) % n])
                d2 = (q[0] - ox) ** 2 + (q[1] - oy) ** 2
                if best is None or d2 < best[0]:
                    best = (d2, q)
        px, py = best[1]
    dx, dy = px - ox, py - oy
    d = (dx * dx + dy * dy) ** 0.5
    return (0.0, 0.0) if d <= 0.0 else (dx / d, dy / d)


def _seg_near(px, py, a, b):
    """The point of segment a-b nearest to (px, py)."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    l2 = dx * dx + dy * dy
    u = 0.0 if l2 <= 0.0 else max(0.0, min(1.0, ((px - a[0]) * dx + (py - a[1]) * dy) / l2))
    return (a[0] + u * dx, a[1] + u * dy)


def _opposed(trace, k, oid, touch):
    o = _obj_at(trace, k, oid)
    dirs = []
    for g in touch:
        other = g["pair"][0] if g["pair"][1] == oid else g["pair"][1]
        p = _body_at(trace, k, other)
        if o is not None and p is not None:
            dirs.append(_towards(o, p))
    for i in range(len(dirs)):
        for j in range(i + 1, len(dirs)):
            a, b = dirs[i], dirs[j]
            if a[0] * b[0] + a[1] * b[1] <= OPPOSED_COS and a[0] * b[0] < 0.0 \
                    and abs(a[0]) >= SIDE and abs(b[0]) >= SIDE:
                return True
    return False


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    contacts = _contacts(trace)
    out = []
    for oid, m in sorted(kin.items()):
        if _is_static(kin, oid) or m["o"][0].get("shape") == "jar":
            continue
        flags, partners = [], []
        mine = [g for g in contacts if oid in g["pair"]]  # this body's contacts, in their order
        for k, v, o in zip(m["k"], m["v"], m["o"]):
            touch = _in_contact(mine, oid, ts[k])
            partners.append(touch)
            flags.append(len(touch) >= 2 and (v[0] ** 2 + v[1] ** 2) ** 0.5 <= REST_V
                         and abs(float(o.get("angular_velocity") or 0.0)) <= ROT_V
                         and _opposed(trace, k, oid, touch))
        for i, j in _runs(m["k"], ts, flags, MIN_S):
            a, b = m["k"][i], m["k"][j]
            det = {oid: _detail(trace, a, b, oid, "wedged object")}
            for g in partners[i]:
                other = g["pair"][0] if g["pair"][1] == oid else g["pair"][1]
                det[other] = _detail(trace, a, b, other, "holding object")
            out.append({"label": "wedged", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": det, "duration_s": round(ts[b] - ts[a], 3)}})
    return out
