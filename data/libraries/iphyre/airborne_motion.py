"""airborne motion: a dynamic object flies free, touching nothing.

One pattern per flight: the stretch between the object's contacts (contact episodes from the event log,
or from the capsule geometry without one) in which it moves at least MOVING_V px/s for at least MIN_S.
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
        for k, v, o in zip(ks, m["v"], m["o"]):
            t = ts[k]
            free = not any(t0 - 1e-9 <= t <= t1 + 1e-9 for t0, t1 in mine)
            flags.append(free and _on_screen(o) and (v[0] ** 2 + v[1] ** 2) ** 0.5 >= MOVING_V)
        for i, j in _runs(ks, ts, flags, MIN_S):
            a, b = ks[i], ks[j]
            c0, c1 = _centre(m["o"][i]), _centre(m["o"][j])
            params = {"object_details": {oid: _detail(trace, a, b, oid, "airborne object")},
                      "duration_s": round(ts[b] - ts[a], 3), "dx_px": round(c1[0] - c0[0], 1),
                      "dy_px": round(c1[1] - c0[1], 1)}
            out.append({"label": "airborne motion", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": params})
    return out
