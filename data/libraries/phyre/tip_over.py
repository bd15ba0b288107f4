"""tip over: a non-ball body (bar, jar, sticks) turns over: a run of frames turning at at least OMEGA
rad/s (recorded angular velocity, else the angle's change over real time) lasting at least MIN_S and
turning at least MIN_TURN rad (about 40 degrees) in all."""

OMEGA = 0.5
MIN_S = 0.2
MIN_TURN = 0.7


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for oid, m in sorted(kin.items()):
        if m["o"][0].get("shape") in ("ball", "wall") or _is_static(kin, oid):
            continue
        ws = [float(o.get("angular_velocity") or 0.0) for o in m["o"]]
        for i, j in _runs(m["k"], ts, [abs(w) >= OMEGA for w in ws], MIN_S):
            turn = abs(float(m["o"][j].get("angle", 0.0)) - float(m["o"][i].get("angle", 0.0)))
            if turn < MIN_TURN:
                continue
            a, b = m["k"][i], m["k"][j]
            out.append({"label": "tip over", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {oid: _detail(trace, a, b, oid, "tipping object",
                                                                       start_angle=round(float(m["o"][i].get("angle", 0.0)), 3),
                                                                       end_angle=round(float(m["o"][j].get("angle", 0.0)), 3))},
                                       "turn_rad": round(turn, 3)}})
    return out
