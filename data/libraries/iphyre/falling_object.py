"""falling object: a dynamic object moves downwards under gravity.

One pattern per fall: a run of frames in which the object's downward velocity is at least FALL_V px/s
(gravity is 100 px/s², so 0.3 s of free fall), lasting at least MIN_S and dropping at least MIN_DROP px,
clipped at the frame it leaves the screen. Velocities are the recorded ones (or displacement over the
real time between frames). Parameters: drop (px), peak downward speed (px/s), whether it left the screen.
"""

FALL_V = 30.0
MIN_S = 0.2
MIN_DROP = 10.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for oid, m in sorted(_kin(trace).items()):
        if not m["o"][0].get("dynamic"):
            continue
        ks = m["k"]
        flags = [v[1] >= FALL_V and _on_screen(o) for v, o in zip(m["v"], m["o"])]
        for i, j in _runs(ks, ts, flags, MIN_S):
            drop = _centre(m["o"][j])[1] - _centre(m["o"][i])[1]
            if drop < MIN_DROP:
                continue
            exits = j + 1 < len(ks) and not _on_screen(m["o"][j + 1])
            a, b = ks[i], ks[j]
            params = {"object_details": {oid: _detail(trace, a, b, oid, "falling object")},
                      "drop_px": round(drop, 1), "peak_speed": round(max(m["v"][x][1] for x in range(i, j + 1)), 1),
                      "leaves_screen": exits}
            out.append({"label": "falling object", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": params})
    return out
