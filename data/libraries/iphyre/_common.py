"""Prelude: helpers every built-in I-PHYRE detector uses: the timestep clock, step lookup by time, the
event log, per-object tracks, centres, velocities (recorded, or from positions over the real time
between frames) and object details.

library.toml prepends it to every detector; it defines no find_pattern."""

MERGE_S = 0.05


def _clock(trace):
    """Timestep indices and times, in order."""
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
    """Position (in the timestep list) of the last timestep at or before time t."""
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
    """The narrowest inclusive step span covering times t0..t1 (one step when an instant falls on a
    step). Returns (start index, end index, start position, end position)."""
    if t1 is None:
        t1 = t0
    a = _at(ts, t0)
    b = _at(ts, t1)
    if ts[b] < t1 and b + 1 < len(ts):
        b += 1
    return idx[a], idx[b], a, b


def _events(trace, kinds):
    """(t, payload) of events of the given kinds, in time order."""
    out = []
    for e in trace.get("events", []):
        if e.get("kind") in kinds and e.get("t") is not None:
            out.append((float(e["t"]), e.get("payload") or {}))
    out.sort(key=lambda x: x[0])
    return out


def _has_contact_log(trace):
    for e in trace.get("events", []):
        if e.get("kind") in ("contact_begin", "contact_end"):
            return True
    return False


def _tracks(trace):
    """{object id: [(timestep position, object dict), ...]} in time order (removed objects stop)."""
    out = {}
    for k, s in enumerate(trace.get("timesteps", [])):
        for o in s.get("objects", []):
            out.setdefault(str(o.get("index")), []).append((k, o))
    return out


def _centre(o):
    return ((float(o.get("x1", 0.0)) + float(o.get("x2", 0.0))) / 2.0,
            (float(o.get("y1", 0.0)) + float(o.get("y2", 0.0))) / 2.0)


def _is_ball(o):
    return o.get("x1") == o.get("x2") and o.get("y1") == o.get("y2")


def _shape(o):
    return "ball" if _is_ball(o) else "block"


def _velocities(track, ts):
    """[(vx, vy)] per entry of a track: the recorded vx, vy, else the centre's displacement divided by
    the real time between the neighbouring frames (frames are not evenly spaced)."""
    out = []
    n = len(track)
    # Each entry's centre once computed, where the formula first needs it; an entry repeating the
    # previous entry's dict (an unchanged object) has its centre.
    cs = [None] * n
    for i, (k, o) in enumerate(track):
        if o.get("vx") is not None and o.get("vy") is not None:
            out.append((float(o["vx"]), float(o["vy"])))
            continue
        a = i - 1 if i > 0 else i
        b = i + 1 if i + 1 < n else i
        dt = ts[track[b][0]] - ts[track[a][0]]
        if a == b or dt <= 0.0:
            out.append((0.0, 0.0))
            continue
        for e in (a, b):
            if cs[e] is None:
                o_e = track[e][1]
                same = e > 0 and cs[e - 1] is not None and track[e - 1][1] is o_e
                cs[e] = cs[e - 1] if same else _centre(o_e)
        ca, cb = cs[a], cs[b]
        out.append(((cb[0] - ca[0]) / dt, (cb[1] - ca[1]) / dt))
    return out


def _obj_at(trace, k, oid):
    for o in trace["timesteps"][k].get("objects", []):
        if str(o.get("index")) == oid:
            return o
    return None


def _xy(o):
    if o is None:
        return None
    c = _centre(o)
    return [round(c[0], 1), round(c[1], 1)]


def _detail(trace, a, b, oid, role, **extra):
    """object_details entry: role, shape, kind flags, and where the object is at the pattern's start and
    end steps (centre, px; None once removed)."""
    oa = _obj_at(trace, a, oid)
    ob = _obj_at(trace, b, oid)
    o = oa or ob or {}
    d = {"role": role, "index": int(o.get("index", -1)) if o else oid, "shape": _shape(o),
         "dynamic": bool(o.get("dynamic", 0)), "eliminable": bool(o.get("eliminable", 0)),
         "radius": float(o.get("radius", 0.0)),
         "start_position": _xy(oa), "end_position": _xy(ob)}
    if o.get("joint"):
        d["joint"] = int(o["joint"])
    if o.get("spring"):
        d["spring"] = int(o["spring"])
    d.update(extra)
    return d


def _kin(trace):
    """{object id: {"k": [timestep positions], "o": [object dicts], "v": [(vx, vy)]}}."""
    _, ts = _clock(trace)
    out = {}
    for oid, tr in _tracks(trace).items():
        out[oid] = {"k": [k for k, _ in tr], "o": [o for _, o in tr], "v": _velocities(tr, ts)}
    return out


def _entry(kin, oid, k):
    """Position in oid's track of its last entry at or before timestep position k (or its first)."""
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


def _speed_at(kin, oid, k):
    if oid not in kin:
        return 0.0
    v = kin[oid]["v"][_entry(kin, oid, k)]
    return (v[0] ** 2 + v[1] ** 2) ** 0.5
