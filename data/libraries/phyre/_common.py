"""Prelude: helpers every built-in PHYRE detector uses: the timestep clock, step lookup by time, the event
log, per-object tracks, velocities (recorded, or displacement over the real time between frames) and
object details (shape, colour, role, positions). Scene pixels, y up.

library.toml prepends it to every detector; it defines no find_pattern."""

MERGE_S = 0.05


def _clock(trace):
    steps = trace.get("timesteps", [])
    try:
        # Every step has both (the usual case): two comprehensions, no call per step.
        return [s["index"] for s in steps], [float(s["t"]) for s in steps]
    except (KeyError, TypeError):
        pass
    # A step without its index (its position) or its time (0).
    idx, ts = [], []
    for s in steps:
        idx.append(s.get("index", len(idx)))
        ts.append(float(s.get("t", 0.0)))
    return idx, ts


def _at(ts, t):
    """Position of the last timestep at or before time t."""
    lo, hi = 0, len(ts) - 1
    if t <= ts[0]:
        return 0
    if t >= ts[hi]:
        return hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ts[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo


def _span(idx, ts, t0, t1=None):
    """Narrowest inclusive step span covering times t0..t1: (start index, end index, start pos, end pos)."""
    if t1 is None:
        t1 = t0
    a = _at(ts, t0)
    b = _at(ts, t1)
    if ts[b] < t1 and b + 1 < len(ts):
        b += 1
    return idx[a], idx[b], a, b


def _kin(trace):
    """{object id: {"k": [timestep positions], "o": [object dicts], "v": [(vx, vy)]}}: the recorded
    velocity where an object has both, else its displacement between the neighbouring entries of its
    track over their time apart (0 for a track of one entry or no time apart)."""
    _, ts = _clock(trace)
    tr = {}
    for k, s in enumerate(trace.get("timesteps", [])):
        for o in s.get("objects", []):
            oid = str(o.get("object_index"))
            t = tr.get(oid)
            if t is None:
                tr[oid] = t = ([], [])
            t[0].append(k)
            t[1].append(o)
    out = {}
    for oid, (ks, os_) in tr.items():
        vs = []
        n = len(ks)
        last = n - 1
        fx, fy = [None] * n, [None] * n  # x and y of an entry once read (as the formula reads them)
        for i in range(n):
            o = os_[i]
            if o.get("vx") is not None and o.get("vy") is not None:
                vs.append((float(o["vx"]), float(o["vy"])))
                continue
            a = i - 1 if i > 0 else 0
            b = i + 1 if i < last else last
            dt = ts[ks[b]] - ts[ks[a]]
            if a == b or dt <= 0.0:
                vs.append((0.0, 0.0))
                continue
            xb = fx[b]
            if xb is None:
                xb = fx[b] = float(os_[b]["x"])
            xa = fx[a]
            if xa is None:
                xa = fx[a] = float(os_[a]["x"])
            vx = (xb - xa) / dt
            yb = fy[b]
            if yb is None:
                yb = fy[b] = float(os_[b]["y"])
            ya = fy[a]
            if ya is None:
                ya = fy[a] = float(os_[a]["y"])
            vs.append((vx, (yb - ya) / dt))
        out[oid] = {"k": ks, "o": os_, "v": vs}
    return out


def _entry(kin, oid, k):
    ks = kin[oid]["k"]
    lo, hi = 0, len(ks) - 1
    if k <= ks[0]:
        return 0
    if k >= ks[hi]:
        return hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ks[mid] <= k:
            lo = mid
        else:
            hi = mid
    return lo


def _vel(kin, oid, k):
    if oid not in kin:
        return (0.0, 0.0)
    return kin[oid]["v"][_entry(kin, oid, k)]


def _speed_at(kin, oid, k):
    v = _vel(kin, oid, k)
    return (v[0] ** 2 + v[1] ** 2) ** 0.5


def _is_static(kin, oid):
    """Never moves in the trace (walls and static bars)."""
    if oid not in kin:
        return True
    return all(abs(v[0]) + abs(v[1]) == 0.0 for v in kin[oid]["v"]) and \
        all(not o.get("angular_velocity") for o in kin[oid]["o"])


def _runs(ks, ts, flags, min_s, gap=MERGE_S):
    """Runs of entries whose flag holds, as (first, last); gaps up to `gap` bridged; runs shorter than
    min_s dropped."""
    out = []
    for i, f in enumerate(flags):
        if not f:
            continue
        if out and (i == out[-1][1] + 1 or ts[ks[i]] - ts[ks[out[-1][1]]] <= gap + 1e-9):
            out[-1][1] = i
        else:
            out.append([i, i])
    # Frame times carry rounding error (8.3 - 8.2 < 0.1): a run of exactly min_s must count.
    return [(a, b) for a, b in out if ts[ks[b]] - ts[ks[a]] >= min_s - 1e-9]


def _obj_at(trace, k, oid):
    for o in trace["timesteps"][k].get("objects", []):
        if str(o.get("object_index")) == oid:
            return o
    return None


def _xy(o):
    return None if o is None else [round(float(o.get("x", 0.0)), 1), round(float(o.get("y", 0.0)), 1)]


def _detail(trace, a, b, oid, role, **extra):
    """object_details entry: role, shape, colour, size, and where the object is at the pattern's start
    and end steps (px, y up)."""
    oa, ob = _obj_at(trace, a, oid), _obj_at(trace, b, oid)
    o = oa or ob or {}
    d = {"role": role, "object_index": int(o.get("object_index", -1)) if o else oid,
         "shape": o.get("shape"), "color": o.get("color"), "diameter": o.get("diameter"),
         "is_user_input": bool(o.get("is_user_input", False)),
         "start_position": _xy(oa), "end_position": _xy(ob)}
    d.update(extra)
    return d
