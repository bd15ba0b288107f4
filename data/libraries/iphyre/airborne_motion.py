"""airborne motion: a dynamic object flies free, touching nothing.

One pattern per flight: a maximal stretch of frames between the object's contacts (contact episodes from
the event log, or from the capsule geometry without one), lasting at least MIN_S, over which it moves at
least MOVING_V px/s on average (path length from its centres over the duration). The whole stretch
counts, so a flight that starts from rest (a block released by a click, a ball at the top of its arc)
is one pattern, not cut where its speed is still low.
Objects held by a joint or a spring are never free and are left out; the flight is clipped where the
object leaves the screen. Parameters: duration, horizontal and vertical travel (px, y down).
"""

MOVING_V = 10.0
MIN_S = 0.15


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    contacts = _contacts(trace)
    out = []
    for oid, m in sorted(_kin(trace).items()):
        o0 = m["o"][0]
        if not o0.get("dynamic") or o0.get("joint") or o0.get("spring"):
            continue
        mine = [(g["t0"], g["t1"]) for g in contacts if oid in g["pair"]]
        ks = m["k"]
        flags = []
        for k, o in zip(ks, m["o"]):
            t = ts[k]
            free = not any(t0 - 1e-9 <= t <= t1 + 1e-9 for t0, t1 in mine)
            flags.append(free and _on_screen(o))
        # Maximal runs: a frame in contact (or off screen) ends a flight.
        for i, j in _runs(ks, ts, flags, MIN_S, 0.0):
            a, b = ks[i], ks[j]
            path = 0.0
            for n in range(i, j):
                p, q = _centre(m["o"][n]), _centre(m["o"][n + 1])
                path += ((q[0] - p[0]) ** 2 + (q[1] - p[1]) ** 2) ** 0.5
            if path < MOVING_V * (ts[b] - ts[a]):
                continue
            c0, c1 = _centre(m["o"][i]), _centre(m["o"][j])
            params = {"object_details": {oid: _detail(trace, a, b, oid, "airborne object")},
                      "duration_s": round(ts[b] - ts[a], 3), "dx_px": round(c1[0] - c0[0], 1),
                      "dy_px": round(c1[1] - c0[1], 1)}
            out.append({"label": "airborne motion", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": params})
    return out
