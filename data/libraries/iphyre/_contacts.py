"""Prelude: contact episodes of object pairs, from the `contact_begin` / `contact_end` events when the
trace has them, else from the capsule geometry of the frames: a contact begins when the gap between the two capsules
is at most CONTACT_GAP px and lasts while it stays at most KEEP_GAP px (a little hysteresis, so a resting
pair does not flicker; README.md says how both were chosen on annotrace's and iphyre's own traces). A pair's contact that begins again within MERGE_S (50 ms) of its end is the same
contact (rapier reports a ball crossing a block joint or resting on two blocks as end/begin chatter).

library.toml prepends it to the detectors that list it; it defines no find_pattern."""

CONTACT_GAP = 0.05
KEEP_GAP = 0.1


def _seg_point(px, py, ax, ay, bx, by):
    """Closest point to (px, py) on segment a-b."""
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    u = 0.0 if l2 <= 0.0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / l2))
    return ax + u * dx, ay + u * dy


def _closest(o1, o2):
    """Closest points (on o1's segment, on o2's segment) and their distance."""
    a = (float(o1["x1"]), float(o1["y1"]), float(o1["x2"]), float(o1["y2"]))
    b = (float(o2["x1"]), float(o2["y1"]), float(o2["x2"]), float(o2["y2"]))
    best = None
    for p, seg, first in (((a[0], a[1]), b, True), ((a[2], a[3]), b, True),
                          ((b[0], b[1]), a, False), ((b[2], b[3]), a, False)):
        q = _seg_point(p[0], p[1], seg[0], seg[1], seg[2], seg[3])
        d = ((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2) ** 0.5
        pts = (p, q) if first else (q, p)
        if best is None or d < best[2]:
            best = (pts[0], pts[1], d)
    # Crossing segments: distance 0 at the crossing.
    c = _crossing(a, b)
    if c is not None:
        return c, c, 0.0
    return best


def _crossing(a, b):
    """The point where segments a and b, each (x1, y1, x2, y2), cross (by the parameters of both
    lines), or None."""
    d1x, d1y, d2x, d2y = a[2] - a[0], a[3] - a[1], b[2] - b[0], b[3] - b[1]
    den = d1x * d2y - d1y * d2x
    if den != 0.0:
        s = ((b[0] - a[0]) * d2y - (b[1] - a[1]) * d2x) / den
        u = ((b[0] - a[0]) * d1y - (b[1] - a[1]) * d1x) / den
        if 0.0 <= s <= 1.0 and 0.0 <= u <= 1.0:
            return (a[0] + s * d1x, a[1] + s * d1y)
    return None


def _gap(o1, o2):
    return _closest(o1, o2)[2] - float(o1.get("radius", 0.0)) - float(o2.get("radius", 0.0))


def _capsule(o, cache, slot):
    """[o, segment as _closest reads it, its extents (x0, x1, y0, y1), all four finite and within a
    million px, radius (None until read)], kept per slot of the step's list while the slot holds the
    same dict."""
    e = cache.get(slot)
    if e is None or e[0] is not o:
        a = (float(o["x1"]), float(o["y1"]), float(o["x2"]), float(o["y2"]))
        ext = (min(a[0], a[2]), max(a[0], a[2]), min(a[1], a[3]), max(a[1], a[3]))
        e = [o, a, ext, all(-1e6 < v < 1e6 for v in a), None]
        cache[slot] = e
    return e


def _gap_far(o1, o2, i, j, cache):
    """KEEP_GAP + 1 for a pair _gap finds more than KEEP_GAP apart because the segments' extents are
    (finite, within a million px, farther apart on an axis than KEEP_GAP and both radii with 1e-6 px to
    spare, and not crossing as _closest tests it); None when _gap must answer. Values are read in
    _gap's order (both segments, then both radii), so a bad one raises as _gap raises."""
    e1, e2 = _capsule(o1, cache, i), _capsule(o2, cache, j)
    r1, r2 = e1[4], e2[4]
    if r1 is None:
        r1 = e1[4] = float(o1.get("radius", 0.0))
    if r2 is None:
        r2 = e2[4] = float(o2.get("radius", 0.0))
    if not (e1[3] and e2[3] and -1e6 < r1 < 1e6 and -1e6 < r2 < 1e6):
        return None
    ea, eb = e1[2], e2[2]
    if max(ea[0] - eb[1], eb[0] - ea[1], ea[2] - eb[3], eb[2] - ea[3]) <= KEEP_GAP + r1 + r2 + 1e-6:
        return None
    if _crossing(e1[1], e2[1]) is not None:
        return None  # _closest answers 0 at the crossing
    return KEEP_GAP + 1.0


def _pair_key(p):
    ag = [str(x) for x in (p.get("agents") or p.get("objects") or [])][:2]
    if len(ag) != 2:
        return None
    return tuple(sorted(ag))


def _contacts(trace):
    """Contact episodes in time order: {pair, t0, t1, begins, ended} with t0 the first begin, t1 the last
    end (or the trace's last time while still touching) and begins the times of merged re-begins. From
    geometry, t0 is the last frame before the touching one and t_seen the first touching frame."""
    idx, ts = _clock(trace)
    if not ts:
        return []
    t_last = ts[-1]
    groups, out = {}, []
    if _has_contact_log(trace):
        evs = []
        for e in trace.get("events", []):
            if e.get("kind") in ("contact_begin", "contact_end") and e.get("t") is not None:
                evs.append((float(e["t"]), e["kind"], e.get("payload") or {}))
        evs.sort(key=lambda x: x[0])
        for t, kind, p in evs:
            key = _pair_key(p)
            if key is None:
                continue
            g = groups.get(key)
            if kind == "contact_end":
                if g is not None:
                    g["t1"] = t
                    g["ended"] = True
                continue
            if t > ts[-1] + 1e-9:
                continue  # after the last frame: no span can hold it
            if g is not None and (not g["ended"] or t - g["t1"] <= MERGE_S):
                g["begins"].append(t)
                g["ended"] = False
                g["t1"] = t_last
                continue
            g = {"pair": key, "t0": t, "t1": t_last, "begins": [t], "ended": False}
            groups[key] = g
            out.append(g)
        return out
    # No event log: touching capsules frame by frame.
    steps = trace["timesteps"]
    # A pair of slots whose objects are the very dicts of the last time it was measured (a step repeats
    # an unchanged object's dict) has the same gap; so does each slot's segment and radius.
    seen, cache = {}, {}
    for k, s in enumerate(steps):
        objs = s.get("objects", [])
        n = len(objs)
        flags = [o.get("dynamic") for o in objs]
        dyn = [j for j in range(n) if flags[j]]
        for i in range(n if dyn else 0):
            o1 = objs[i]
            for j in range(i + 1, n) if flags[i] else [j for j in dyn if j > i]:
                o2 = objs[j]
                c = seen.get((i, j))
                if c is not None and c[0] is o1 and c[1] is o2:
                    gap = c[2]
                else:
                    gap = _gap_far(o1, o2, i, j, cache)
                    if gap is None:
                        gap = _gap(o1, o2)
                    seen[(i, j)] = (o1, o2, gap)
                if gap > KEEP_GAP:
                    continue
                key = tuple(sorted((str(o1.get("index")), str(o2.get("index")))))
                g = groups.get(key)
                if gap > CONTACT_GAP and (g is None or g["last_k"] != k - 1):
                    continue
                if g is not None and (g["last_k"] == k - 1 or ts[k] - g["t1"] <= MERGE_S):
                    if g["last_k"] != k - 1:
                        g["begins"].append(ts[k])
                    g["t1"] = ts[k]
                    g["last_k"] = k
                    continue
                # The contact began between the previous frame and this one (objects touching in
                # the first frame: as the simulation starts, up to the next frame).
                t_prev = ts[k - 1] if k > 0 else ts[0]
                t_seen = ts[k] if k > 0 else ts[min(1, len(ts) - 1)]
                g = {"pair": key, "t0": t_prev, "t_seen": t_seen, "t1": ts[k], "begins": [t_prev],
                     "ended": True, "last_k": k}
                groups[key] = g
                out.append(g)
    out.sort(key=lambda g: g["t0"])
    return out


def _touching(contacts, oid, t0, t1):
    """The contact episodes of object oid overlapping [t0, t1]."""
    return [g for g in contacts if oid in g["pair"] and g["t0"] <= t1 and g["t1"] >= t0]
