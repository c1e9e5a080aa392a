#!/usr/bin/env bash
# scripts/check-layers.py must fail on a tree that breaks the layering, naming each offending
# include - a folder above or beside, apps/ from a layer, and each library of its rule table below
# its layer - and pass the same tree once the offending includes are gone, the libraries still
# included at their own layers (docs/architecture.md).
set -euo pipefail
checker=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp"/{runtime/core,proto/dds,proto/http,renderer/assets,engine,worker,coordinator/monitoring}
mkdir -p "$tmp"/apps/{poseforest,commands,devices,live,ros2}
echo '#pragma once' > "$tmp/runtime/core/result.h"
echo '#pragma once' > "$tmp/engine/sample_set.h"
echo '#pragma once' > "$tmp/coordinator/dist_coordinator.h"
echo '#pragma once' > "$tmp/apps/commands/commands.h"

# Allowed: project folders below, and each library at its own layer or above.
printf '#include "runtime/core/result.h"\n#include "poseforest/v1/wire.pb.h"\n' > "$tmp/proto/dds/ok.cpp"
printf '#include <fastdds/dds/domain/DomainParticipant.hpp>\n#include <fastrtps/utils/IPLocator.h>\n' >> "$tmp/proto/dds/ok.cpp"
printf '#include <fastcdr/Cdr.h>\n#include <google/protobuf/message.h>\n' >> "$tmp/proto/dds/ok.cpp"
printf '#include <httplib.h>\n' > "$tmp/proto/http/ok.cpp"
printf '#include <EGL/egl.h>\n#include <GLES3/gl3.h>\n#include "runtime/core/result.h"\n' > "$tmp/renderer/ok.cpp"
printf '#include <assimp/scene.h>\n' > "$tmp/renderer/assets/ok.cpp"
printf '#include <google/protobuf/text_format.h>\n#include <Eigen/Dense>\n#include <omp.h>\n' > "$tmp/engine/ok.cpp"
printf '#include "engine/sample_set.h"\n' > "$tmp/worker/ok.cpp"
printf '#include <google/protobuf/util/json_util.h>\n' > "$tmp/coordinator/monitoring/ok.cpp"
printf '#include "apps/commands/commands.h"\n#include "coordinator/dist_coordinator.h"\n' > "$tmp/apps/poseforest/main.cpp"
printf '#include <libfreenect.h>\n#include <OpenNI.h>\n#include "runtime/core/result.h"\n' > "$tmp/apps/devices/ok.cpp"
printf '#include <httplib.h>\n' > "$tmp/apps/live/ok.cpp"
printf '#include <fastdds/dds/publisher/DataWriter.hpp>\n#include <fastcdr/Cdr.h>\n' > "$tmp/apps/ros2/ok.cpp"
printf '#include <Eigen/Dense>\n#include <omp.h>\n#include <vector>\n' > "$tmp/runtime/ok.cpp"

# Refused: each on its own line of its own file.
printf '#include "runtime/core/result.h"\n#include "engine/sample_set.h"\n' > "$tmp/runtime/core/up.cpp"
printf '#include "coordinator/dist_coordinator.h"\n' > "$tmp/worker/sibling.cpp"
printf '#include "poseforest/v1/job.pb.h"\n' > "$tmp/runtime/generated.cpp"
printf '#include "apps/commands/commands.h"\n' > "$tmp/engine/apps.cpp"
printf '#include <vector>\n#include <fastdds/dds/domain/DomainParticipant.hpp>\n' > "$tmp/runtime/fastdds.cpp"
printf '#include <fastrtps/utils/IPLocator.h>\n' > "$tmp/runtime/fastrtps.cpp"
printf '#include <fastcdr/Cdr.h>\n' > "$tmp/runtime/core/fastcdr.cpp"
printf '#include <google/protobuf/message.h>\n' > "$tmp/runtime/protobuf.cpp"
printf '#include <httplib.h>\n' > "$tmp/runtime/httplib.cpp"
printf '#include <EGL/egl.h>\n' > "$tmp/proto/dds/egl.cpp"
printf '#include <GLES3/gl3.h>\n' > "$tmp/runtime/gles.cpp"
printf '#include <assimp/scene.h>\n' > "$tmp/proto/assimp.cpp"
printf '#include <libfreenect.h>\n' > "$tmp/runtime/freenect.cpp"
printf '#include <OpenNI.h>\n' > "$tmp/coordinator/openni.cpp"
printf '#include <libfreenect.h>\n' > "$tmp/engine/freenect.cpp"
bad="runtime/core/up.cpp worker/sibling.cpp runtime/generated.cpp engine/apps.cpp runtime/fastdds.cpp
     runtime/fastrtps.cpp runtime/core/fastcdr.cpp runtime/protobuf.cpp runtime/httplib.cpp proto/dds/egl.cpp
     runtime/gles.cpp proto/assimp.cpp runtime/freenect.cpp coordinator/openni.cpp engine/freenect.cpp"

set +e
out=$(python3 "$checker" "$tmp" 2>&1)
rc=$?
set -e
echo "$out"
[ $rc -eq 1 ] || { echo "FAIL: exit $rc on a tree with offending includes (want 1)"; exit 1; }
while IFS= read -r want; do
  grep -qF "$want" <<< "$out" || { echo "FAIL: not named: $want"; exit 1; }
done <<'WANT'
runtime/core/up.cpp:2: runtime/ includes engine/sample_set.h
worker/sibling.cpp:1: worker/ includes coordinator/dist_coordinator.h
runtime/generated.cpp:1: runtime/ includes poseforest/v1/job.pb.h
engine/apps.cpp:1: engine/ includes apps/commands/commands.h (apps/ is not below engine/)
runtime/fastdds.cpp:2: runtime/ includes <fastdds/dds/domain/DomainParticipant.hpp> (Fast DDS is for proto/ and above)
runtime/fastrtps.cpp:1: runtime/ includes <fastrtps/utils/IPLocator.h> (Fast DDS is for proto/ and above)
runtime/core/fastcdr.cpp:1: runtime/ includes <fastcdr/Cdr.h> (Fast DDS is for proto/ and above)
runtime/protobuf.cpp:1: runtime/ includes <google/protobuf/message.h> (Protobuf is for proto/ and above)
runtime/httplib.cpp:1: runtime/ includes <httplib.h> (cpp-httplib is for proto/ and above)
proto/dds/egl.cpp:1: proto/ includes <EGL/egl.h> (EGL/GLES is for renderer/ and above)
runtime/gles.cpp:1: runtime/ includes <GLES3/gl3.h> (EGL/GLES is for renderer/ and above)
proto/assimp.cpp:1: proto/ includes <assimp/scene.h> (Assimp is for renderer/ and above)
runtime/freenect.cpp:1: runtime/ includes <libfreenect.h> (libfreenect is for apps/ and above)
coordinator/openni.cpp:1: coordinator/ includes <OpenNI.h> (OpenNI2 is for apps/ and above)
engine/freenect.cpp:1: engine/ includes <libfreenect.h> (libfreenect is for apps/ and above)
WANT
[ "$(grep -c ' includes ' <<< "$out")" -eq 15 ] || { echo "FAIL: want exactly 15 offending includes"; exit 1; }
for f in $bad; do rm "$tmp/$f"; done
python3 "$checker" "$tmp" || { echo "FAIL: a clean tree was refused"; exit 1; }
echo "ok: upward, sibling and apps/ includes and the rule table's libraries below their layers refused and named;"
echo "    the same libraries at their layers (and a clean tree) pass"
