"""lever launch: a turning block flings an object resting on it upwards.

Within a contact episode between a dynamic block (the lever) and another dynamic object, the frames in
which the lever turns at at least OMEGA rad/s and the object rises at at least LAUNCH_V px/s (upwards,
screen y grows down) — from the first such frame to the frame the object leaves the lever (contact end,
capped at MAX_S). Parameters: peak upward speed (px/s) and the lever's angular speed (rad/s).
"""

OMEGA = 0.3
LAUNCH_V = 40.0
MAX_S = 1.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        for lever, obj in (g["pair"], g["pair"][::-1]):
            if lever not in kin or obj not in kin:
                continue
            lo, oo = kin[lever]["o"][0], kin[obj]["o"][0]
            if not lo.get("dynamic") or _is_ball(lo) or not oo.get("dynamic"):
                continue
            a0, b0 = _at(ts, g["t0"]), _at(ts, g["t1"])
            start = None
            for k in range(a0, b0 + 1):
                if _obj_at(trace, k, obj) is None or _obj_at(trace, k, lever) is None:
                    break
                if abs(_spin(kin, lever, k, ts)) >= OMEGA and _vel(kin, obj, k)[1] <= -LAUNCH_V:
                    start = k
                    break
            if start is None:
                continue
            end = min(_at(ts, min(g["t1"], ts[start] + MAX_S)) + (0 if g["t1"] >= ts[-1] else 1), len(ts) - 1)
            peak = max(-_vel(kin, obj, k)[1] for k in range(start, end + 1))
            om = max(abs(_spin(kin, lever, k, ts)) for k in range(start, end + 1))
            out.append({"label": "lever launch", "start_timestep": idx[start], "end_timestep": idx[end],
                        "parameters": {"object_details": {lever: _detail(trace, start, end, lever, "lever"),
                                                          obj: _detail(trace, start, end, obj, "launched object")},
                                       "peak_upward_speed": round(peak, 1), "lever_angular_speed": round(om, 3)}})
    return out
