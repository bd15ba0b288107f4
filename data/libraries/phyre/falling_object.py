"""falling object: a dynamic body moves downwards (y up) at at least FALL_V px/s for at least MIN_S,
dropping at least MIN_DROP px. One pattern per fall; velocities recorded (or displacement over real
time between frames)."""

FALL_V = 30.0
MIN_S = 0.2
MIN_DROP = 10.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for oid, m in sorted(_kin(trace).items()):
        for i, j in _runs(m["k"], ts, [v[1] <= -FALL_V for v in m["v"]], MIN_S):
            drop = float(m["o"][i]["y"]) - float(m["o"][j]["y"])
            if drop < MIN_DROP:
                continue
            a, b = m["k"][i], m["k"][j]
            out.append({"label": "falling object", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {oid: _detail(trace, a, b, oid, "falling object")},
                                       "drop_px": round(drop, 1),
                                       "peak_speed": round(-min(m["v"][x][1] for x in range(i, j + 1)), 1)}})
    return out
