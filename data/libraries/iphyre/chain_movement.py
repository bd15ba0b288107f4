"""chain movement: motion passes along a chain of objects, each set moving by the one before.

A transfer is either a collision (contact begin, chatter merged) in which a striker moving at least
MOVING_V px/s hits a dynamic object at rest (at most REST_V px/s in the frame before) that moves at least
MOVING_V within START_S after, a pull through a spring or joint: an object at rest whose spring/joint
partner started moving before it starts moving itself within START_S, or a release: a click removes a
block (`action_applied`, or without events an eliminable block vanishing) and a dynamic object at rest touching it starts moving within RELEASE_S. Transfers link into a chain when
the object set moving by one moves the next within GAP_S. A chain of at least two transfers (three
objects) is one pattern, from the first transfer to the last; roles name each object's place in the
chain and parameters say how each link passed the motion on.
"""

MOVING_V = 15.0
REST_V = 2.0
START_S = 0.2
RELEASE_S = 0.5
GAP_S = 2.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    transfers = []
    for g in _contacts(trace):
        c = _at(ts, g["t0"])
        pre = max(c - 1, 0)
        for hitter, hit in (g["pair"], g["pair"][::-1]):
            if hitter not in kin or hit not in kin or not kin[hit]["o"][0].get("dynamic"):
                continue
            if _speed_at(kin, hitter, pre) < MOVING_V or _speed_at(kin, hit, pre) > REST_V:
                continue
            k, moved = c, False
            while k < len(ts) and ts[k] <= ts[c] + START_S:
                if _speed_at(kin, hit, k) >= MOVING_V:
                    moved = True
                    break
                k += 1
            if moved:
                transfers.append((g["t0"], hitter, hit, "collision"))
    # Pulls through springs and joints: motion onsets (first frame at MOVING_V after one at REST_V).
    onsets = {}
    for oid, m in kin.items():
        sp = [(v[0] ** 2 + v[1] ** 2) ** 0.5 for v in m["v"]]
        rest = False
        for n, k in enumerate(m["k"]):
            if sp[n] <= REST_V:
                rest = True
            elif rest and sp[n] >= MOVING_V:
                onsets.setdefault(oid, []).append(ts[k])
                rest = False
    links = {}
    for oid, m in kin.items():
        for kind in ("spring", "joint"):
            c = m["o"][0].get(kind)
            if c:
                links.setdefault((kind, c), []).append(oid)
    for (kind, _), ids in links.items():
        if len(ids) != 2:
            continue
        for p, q in (ids, ids[::-1]):
            for tq in onsets.get(q, []):
                if any(0.0 < tq - tp <= START_S for tp in onsets.get(p, [])):
                    transfers.append((tq, p, q, kind))
    removals = [(t, str(p.get("eliminated_object"))) for t, p in _events(trace, ("action_applied",))
                if p.get("effective") is True]
    if not _events(trace, ("action_applied", "scheduled_action")):
        # No event log: an eliminable block that vanishes between two frames was removed.
        for oid, m in kin.items():
            k_last = m["k"][-1]
            if m["o"][-1].get("eliminable") and k_last + 1 < len(ts):
                removals.append((ts[k_last + 1], oid))
    for t, gone in removals:
        pre = max(_at(ts, t) - 1, 0)
        og = _obj_at(trace, pre, gone)
        if og is None:
            continue
        for o in trace["timesteps"][pre].get("objects", []):
            oid = str(o.get("index"))
            if oid == gone or not o.get("dynamic") or _gap(og, o) > KEEP_GAP:
                continue
            if _speed_at(kin, oid, pre) > REST_V:
                continue
            k = pre
            while k < len(ts) and ts[k] <= t + RELEASE_S:
                if _speed_at(kin, oid, k) >= MOVING_V:
                    transfers.append((t, gone, oid, "removal"))
                    break
                k += 1
    transfers.sort()
    used = set()
    out = []
    for i, first in enumerate(transfers):
        if i in used:
            continue
        chain = [first]
        used.add(i)
        for j in range(i + 1, len(transfers)):
            t, hitter, hit, _ = transfers[j]
            if j not in used and hitter == chain[-1][2] and 0.0 < t - chain[-1][0] <= GAP_S + 1e-9 \
                    and hit not in [c[1] for c in chain]:
                chain.append(transfers[j])
                used.add(j)
        if len(chain) < 2:
            continue
        s, e, a, b = _span(idx, ts, chain[0][0], chain[-1][0])
        det = {chain[0][1]: _detail(trace, a, b, chain[0][1], "initiator", order=0)}
        for n, (_, _, hit, _) in enumerate(chain):
            role = "last moved" if n == len(chain) - 1 else "link"
            det[hit] = _detail(trace, a, b, hit, role, order=n + 1)
        out.append({"label": "chain movement", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": det, "links": len(chain),
                                   "times": [round(c[0], 4) for c in chain],
                                   "via": [c[3] for c in chain]}})
    return out
