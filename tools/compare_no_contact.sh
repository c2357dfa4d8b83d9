#!/bin/bash
# No-contact scenarios with two checkouts' code in one command, alternating, 3 repeats each:
#   tools/compare_no_contact.sh /path/to/main-worktree /path/to/this-worktree
# prints: checkout, scenario, runtime_s, iterations, error (docs/contact.md section 8.3)
for rep in 1 2 3; do
for tree in "$@"; do
  for sc in "straight_twist.py --n 400" "ring_torsion.py --n 400" "helix_torque.py --n 400"; do
    r=$(cd "$tree" && PYTHONPATH="$tree" python scenarios/$sc --json 2>/dev/null | tail -1 | python -c "import json,sys; d=json.loads(sys.stdin.read()); print(d.get('runtime_s'), d.get('iterations'), d.get('error'))")
    echo "$(basename "$tree") $sc $r"
  done
done
done
