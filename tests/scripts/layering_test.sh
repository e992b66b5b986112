#!/usr/bin/env bash
# The rooms' layering rules (docs/architecture.md "Rooms and rules"), checked two ways:
#  1. includes: each room's sources include headers only from the rooms it may use;
#  2. links: no library reaches (directly or through others) a library its room must not use,
#     read from the link graph CMake wrote at configure time (build/perch_link_graph.txt).
# Usage: layering_test.sh SOURCE_DIR BUILD_DIR. Exit 1 naming each broken rule.
set -euo pipefail
src=$1
build=$2
python3 - "$src" "$build/perch_link_graph.txt" <<'PY'
import os, re, shutil, sys, tempfile
src, graph_path = sys.argv[1], sys.argv[2]
# Room -> the rooms its sources may include (its own always). Floors, lowest first.
may_include = {
    'common': [],
    'envs': ['common'],
    'policy': ['common'],
    'protocol': ['common', 'policy'],
    'motion': ['common', 'envs'],
    'viz': ['common', 'envs', 'motion'],
    'tasks': ['common', 'envs', 'motion', 'policy'],
    'hierarchy': ['common', 'envs', 'motion', 'policy', 'tasks'],
    'eval': ['common', 'envs', 'motion', 'policy', 'tasks', 'hierarchy', 'viz'],
    'experiment': ['common', 'envs', 'motion', 'policy', 'protocol', 'tasks', 'hierarchy'],
    'learner': ['common', 'policy', 'protocol'],
    'learner/local': ['common', 'envs', 'motion', 'policy', 'protocol', 'tasks', 'hierarchy',
                      'experiment', 'learner'],
    'learner/service': ['common', 'policy', 'protocol', 'experiment', 'learner'],
    'actor': ['common', 'envs', 'motion', 'policy', 'protocol', 'tasks', 'experiment'],
    'launch': ['common', 'envs', 'motion', 'policy', 'protocol', 'tasks', 'experiment', 'learner',
               'learner/service', 'actor'],
    'bench': ['common', 'envs', 'motion', 'policy', 'protocol', 'tasks', 'experiment', 'learner',
              'learner/service', 'actor'],
    'recipe': ['common', 'actor'],
}
# Library -> libraries it must never reach, however indirectly.
training = ['perch_learner', 'perch_learner_local', 'perch_learner_service']
must_not_link = {
    'perch_common': ['perch_envs', 'perch_policy', 'perch_protocol', 'perch_tasks'],
    'perch_envs': ['perch_policy', 'perch_tasks', 'perch_viz'] + training,
    'perch_policy': ['perch_envs', 'perch_protocol', 'perch_tasks'] + training,
    'perch_protocol': ['perch_envs', 'perch_tasks', 'perch_experiment'] + training,
    'perch_viz': ['perch_tasks', 'perch_policy'] + training,
    'perch_tasks': ['perch_hierarchy', 'perch_viz', 'perch_protocol', 'perch_experiment',
                    'perch_actor'] + training,
    'perch_hierarchy': ['perch_viz', 'perch_protocol', 'perch_experiment', 'perch_actor'] + training,
    'perch_eval': ['perch_protocol', 'perch_experiment', 'perch_actor'] + training,
    'perch_experiment': ['perch_viz', 'perch_actor'] + training,
    'perch_learner': ['perch_envs', 'perch_tasks', 'perch_experiment', 'perch_actor',
                      'perch_learner_service', 'perch_learner_local'],
    'perch_actor': ['perch_viz'] + training,
}
rooms = sorted(may_include, key=len, reverse=True)
def room_of(path):
    for r in rooms:
        if path == r or path.startswith(r + '/'):
            return r
    return None
inc_re = re.compile(r'^\s*#\s*include\s+"([a-z_]+(?:/[a-z_]+)*)/[A-Za-z0-9_.]+"', re.M)


def check(src, graph_path):
    """The broken rules of the tree at src with the link graph at graph_path, and the count of
    includes checked."""
    bad, checked = [], 0
    for room in may_include:
        d = os.path.join(src, room)
        for name in sorted(os.listdir(d)) if os.path.isdir(d) else []:
            if not name.endswith(('.h', '.cc', '.inc')):
                continue
            text = open(os.path.join(d, name), encoding='utf-8').read()
            for m in inc_re.finditer(text):
                target = room_of(m.group(1))
                checked += 1
                if target is None or target == room or target in may_include[room]:
                    continue
                bad.append('%s/%s includes "%s/...": %s/ may use only %s' %
                           (room, name, m.group(1), room,
                            ', '.join(may_include[room]) or 'itself'))
    graph = {}
    for line in open(graph_path):
        if ':' in line:
            lib, deps = line.split(':', 1)
            graph[lib.strip()] = [x for x in re.split(r'[;\s]+', deps) if x.startswith('perch_')]

    def reach(lib):
        seen, todo = {}, [(lib, [lib])]
        while todo:
            cur, path = todo.pop()
            for d in graph.get(cur, []):
                if d not in seen:
                    seen[d] = path + [d]
                    todo.append((d, path + [d]))
        return seen

    for lib, banned in must_not_link.items():
        if lib not in graph:
            bad.append('%s: not in the link graph %s' % (lib, graph_path))
            continue
        r = reach(lib)
        for b in banned:
            if b in r:
                bad.append('%s links %s (%s)' % (lib, b, ' -> '.join(r[b])))
    return bad, checked


# First, that a break is seen: a task that includes PPO, and tasks linking the learner through
# another library.
tmp = tempfile.mkdtemp()
os.makedirs(os.path.join(tmp, 'tasks'))
with open(os.path.join(tmp, 'tasks', 'x.cc'), 'w') as f:
    f.write('#include "learner/ppo.h"\n#include "policy/policy.h"\n#include "hierarchy/meta_env.h"\n')
with open(os.path.join(tmp, 'graph.txt'), 'w') as f:
    for lib in must_not_link:
        f.write('%s: perch_common\n' % lib)
    f.write('perch_tasks: perch_policy;perch_motion\nperch_motion: perch_learner_local\n')
seen, _ = check(tmp, os.path.join(tmp, 'graph.txt'))
shutil.rmtree(tmp)
want = ['tasks/x.cc includes "learner/...', 'tasks/x.cc includes "hierarchy/...', 'perch_tasks links perch_learner_local (perch_tasks -> perch_motion']
for w in want:
    if not any(b.startswith(w) for b in seen):
        print('layering: the check missed a planted break: %s (saw %s)' % (w, seen))
        sys.exit(1)

bad, checked = check(src, graph_path)
if bad:
    print('layering: %d broken rule(s):' % len(bad))
    for b in bad:
        print('  ' + b)
    sys.exit(1)
print('layering: %d includes in %d rooms and %d libraries\' links follow the rules' %
      (checked, len(may_include), len(must_not_link)))
PY
