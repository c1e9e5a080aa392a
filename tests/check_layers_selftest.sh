#!/usr/bin/env bash
# scripts/check-layers.py must fail on a tree that breaks the layering, naming each offending
# include, and pass the same tree once the includes are gone (docs/architecture.md).
set -euo pipefail
checker=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp"/{runtime/core,proto/dds,renderer,engine,worker,coordinator/monitoring}
echo '#pragma once' > "$tmp/runtime/core/result.h"
echo '#pragma once' > "$tmp/engine/sample_set.h"
echo '#pragma once' > "$tmp/coordinator/dist_coordinator.h"
printf '#include "runtime/core/result.h"\n#include "poseforest/v1/wire.pb.h"\n' > "$tmp/proto/dds/ok.cpp"
printf '#include "engine/sample_set.h"\n' > "$tmp/worker/ok.cpp"
printf '#include "runtime/core/result.h"\n#include "engine/sample_set.h"\n' > "$tmp/runtime/core/up.cpp"
printf '#include "coordinator/dist_coordinator.h"\n' > "$tmp/worker/sibling.cpp"
printf '#include "poseforest/v1/job.pb.h"\n' > "$tmp/runtime/generated.cpp"
set +e
out=$(python3 "$checker" "$tmp" 2>&1)
rc=$?
set -e
echo "$out"
[ $rc -eq 1 ] || { echo "FAIL: exit $rc on a tree with upward includes (want 1)"; exit 1; }
for want in "runtime/core/up.cpp:2: runtime/ includes engine/sample_set.h" \
            "worker/sibling.cpp:1: worker/ includes coordinator/dist_coordinator.h" \
            "runtime/generated.cpp:1: runtime/ includes poseforest/v1/job.pb.h"; do
  grep -qF "$want" <<< "$out" || { echo "FAIL: not named: $want"; exit 1; }
done
[ "$(grep -c ' includes ' <<< "$out")" -eq 3 ] || { echo "FAIL: want exactly 3 offending includes"; exit 1; }
rm "$tmp/runtime/core/up.cpp" "$tmp/worker/sibling.cpp" "$tmp/runtime/generated.cpp"
python3 "$checker" "$tmp" || { echo "FAIL: a clean tree was refused"; exit 1; }
echo "ok: upward and sibling includes refused and named, a clean tree passes"
