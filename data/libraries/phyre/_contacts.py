"""Prelude: contact episodes of object pairs from the `contact_begin` / `contact_end` events, a pair's
contact that begins again within MERGE_S (50 ms) of its end being the same contact (a bouncing or
rocking body chatters). Without an event log, contacts of balls are found from geometry: two balls whose
surfaces are at most CONTACT_GAP px apart, or a ball at most that far from a wall (the four walls
bound the 256 px scene); other shapes have no geometric fallback (PHYRE traces do not carry the
outlines of bars, jars and sticks).

library.toml prepends it to the detectors that list it; it defines no find_pattern."""

CONTACT_GAP = 1.5
SCENE = 256.0


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
    for k, s in enumerate(trace["timesteps"]):
        balls = [o for o in s.get("objects", []) if o.get("shape") == "ball"]
        walls = [o for o in s.get("objects", []) if o.get("shape") == "wall"]
        touching = []
        for i, o in enumerate(balls):
            r = float(o.get("diameter", 0.0)) / 2.0
            x, y = float(o["x"]), float(o["y"])
            for w in walls:
                wx, wy = float(w["x"]), float(w["y"])
                gap = y - r if wy < 0.0 else (SCENE - y - r if wy > SCENE else
                                               (x - r if wx < 0.0 else SCENE - x - r))
                if gap <= CONTACT_GAP:
                    touching.append((str(w["object_index"]), str(o["object_index"]), gap))
            for q in balls[i + 1:]:
                d = ((float(o["x"]) - float(q["x"])) ** 2 + (float(o["y"]) - float(q["y"])) ** 2) ** 0.5
                gap = d - r - float(q.get("diameter", 0.0)) / 2.0
                if gap <= CONTACT_GAP:
                    touching.append((str(o["object_index"]), str(q["object_index"]), gap))
        for a, b, gap in touching:
            key = tuple(sorted((a, b)))
            g = groups.get(key)
            if g is not None and (g["last_k"] == k - 1 or ts[k] - g["t1"] <= MERGE_S):
                g["t1"], g["last_k"] = ts[k], k
                continue
            # The contact began after the previous frame: by this frame when the bodies already press
            # together, else (a gap of up to CONTACT_GAP) possibly only before the next one.
            t0 = ts[k - 1] if k > 0 else ts[0]
            t_seen = ts[k] if gap <= 0.0 or k + 1 >= len(ts) else ts[k + 1]
            g = {"pair": key, "t0": t0, "t_seen": t_seen, "t1": ts[k], "begins": [t0], "ended": True,
                 "last_k": k}
            groups[key] = g
            out.append(g)
    out.sort(key=lambda g: g["t0"])
    return out


def _in_contact(contacts, oid, t):
    return [g for g in contacts if oid in g["pair"] and g["t0"] - 1e-9 <= t <= g["t1"] + 1e-9]
