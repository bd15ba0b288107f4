import hashlib, json, phyre
res = {}
for setup in ['ball_within_template', 'ball_cross_template']:
    for seed in range(10):
        tr, dv, te = phyre.get_fold(setup, seed)
        h = lambda ids: hashlib.sha256('\n'.join(ids).encode()).hexdigest()
        res[f'{setup}/{seed}'] = {'train': [len(tr), h(tr)], 'dev': [len(dv), h(dv)], 'test': [len(te), h(te)],
            'test_templates': sorted({t.split(':')[0] for t in te}), 'first_test': te[:3]}
print(json.dumps(res, indent=1))
