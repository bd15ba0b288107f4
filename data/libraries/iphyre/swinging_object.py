"""swinging object: an object on a joint swings, the rod joining it to its partner turning.

Objects sharing a nonzero `joint` id are held at a fixed distance (a pin joint). The rod's direction is
the vector between their centres; its turning rate comes from the change of direction between frames
over the real time between them (small-angle cross product, no trigonometry needed). A swing is a run of
frames turning at least OMEGA rad/s for at least MIN_S, turning MIN_DEG degrees or more in all; the slow
frames at a turning point (up to TURN_S) do not split it, so one pattern holds the back-and-forth. The swinging
object is the one that moved more; parameters: total angle swung and the number of direction reversals.
"""

OMEGA = 0.2
MIN_S = 0.3
TURN_S = 0.4
MIN_DEG = 10.0
DEG = 57.29578


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    joints = {}
    for oid, m in kin.items():
        j = m["o"][0].get("joint")
        if j:
            joints.setdefault(j, []).append(oid)
    out = []
    for j, ids in sorted(joints.items()):
        if len(ids) != 2:
            continue
        p, q = sorted(ids)
        ks = [k for k in kin[p]["k"] if k in set(kin[q]["k"])]
        if len(ks) < 3:
            continue
        rates = [0.0]
        for n in range(1, len(ks)):
            a, b = _obj_at(trace, ks[n - 1], p), _obj_at(trace, ks[n - 1], q)
            c, d = _obj_at(trace, ks[n], p), _obj_at(trace, ks[n], q)
            ca, cb, cc, cd = _centre(a), _centre(b), _centre(c), _centre(d)
            u = (cb[0] - ca[0], cb[1] - ca[1])
            w = (cd[0] - cc[0], cd[1] - cc[1])
            nn = (u[0] ** 2 + u[1] ** 2) ** 0.5 * (w[0] ** 2 + w[1] ** 2) ** 0.5
            dt = ts[ks[n]] - ts[ks[n - 1]]
            rates.append(0.0 if nn <= 0.0 or dt <= 0.0 else (u[0] * w[1] - u[1] * w[0]) / nn / dt)
        flags = [abs(r) >= OMEGA for r in rates]
        for i, k in _runs(ks, ts, flags, MIN_S, TURN_S):
            total, rev, sign = 0.0, 0, 0
            for n in range(i + 1, k + 1):
                total += abs(rates[n]) * (ts[ks[n]] - ts[ks[n - 1]])
                sg = 1 if rates[n] > 0 else (-1 if rates[n] < 0 else 0)
                if sg and sign and sg != sign:
                    rev += 1
                if sg:
                    sign = sg
            if total * DEG < MIN_DEG:
                continue
            a, b = ks[i], ks[k]
            dp = sum(abs(_speed_at(kin, p, x)) for x in ks[i:k + 1])
            dq = sum(abs(_speed_at(kin, q, x)) for x in ks[i:k + 1])
            bob, pivot = (p, q) if dp >= dq else (q, p)
            params = {"object_details": {bob: _detail(trace, a, b, bob, "swinging object"),
                                         pivot: _detail(trace, a, b, pivot, "joint partner")},
                      "joint": j, "swing_deg": round(total * DEG, 1), "reversals": rev}
            out.append({"label": "swinging object", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": params})
    return out
