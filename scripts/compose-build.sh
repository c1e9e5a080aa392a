#!/bin/bash
# Builds the images of deploy/compose.yaml from this repository, with Debian packages only:
# the base image (deploy/docker/make-base-image.sh: debootstrap + import, when TAG is missing),
# then poseforest-discovery, poseforest-coordinator, poseforest-worker and poseforest-prometheus
# from deploy/docker/Dockerfile.*.
#
#   scripts/compose-build.sh            # the working tree as git sees it (tracked + untracked, not ignored)
#   scripts/compose-build.sh prometheus worker   # only these (discovery, prometheus, coordinator, worker)
#   POSEFOREST_BUILD_CONTEXT=head scripts/compose-build.sh   # `git archive HEAD` instead
#   ENGINE=podman scripts/compose-build.sh
#
# Why not `docker compose build`: the context is sent as a tar of the files git knows, without
# build*/, .git and out/. The legacy builder (Debian's docker.io 20.10 without buildx, and
# docker-compose 1.29) reads only a .dockerignore at the context's root, not the per-Dockerfile
# deploy/docker/Dockerfile.X.dockerignore that BuildKit reads, and would send the build trees.
# With BuildKit and compose v2, `docker compose -f deploy/compose.yaml build` works as well.
# Builds use the host's network (`--network host`): apt-get reaches Debian's mirror, and the
# daemon needs no bridge or NAT rules for it. The coordinator and worker share their build stage
# (same instructions, same context), so the second image reuses the first's compile.
set -euo pipefail

ENGINE=${ENGINE:-docker}
DEBIAN_IMAGE=${POSEFOREST_DEBIAN:-debian:12}
CONTEXT=${POSEFOREST_BUILD_CONTEXT:-worktree}
repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"

if ! "$ENGINE" image inspect "$DEBIAN_IMAGE" >/dev/null 2>&1; then
  echo "compose-build.sh: no $DEBIAN_IMAGE image; making it from Debian packages"
  ENGINE=$ENGINE deploy/docker/make-base-image.sh "$DEBIAN_IMAGE"
fi

context_tar() {
  case "$CONTEXT" in
    head) git archive --format=tar HEAD ;;
    worktree) git ls-files -z --cached --others --exclude-standard |
                while IFS= read -r -d '' f; do [ -e "$f" ] && printf '%s\0' "$f"; done |
                tar --null -T - -c ;;
    *) echo "compose-build.sh: POSEFOREST_BUILD_CONTEXT is worktree or head, not $CONTEXT" >&2; exit 2 ;;
  esac
}

build() {  # build DOCKERFILE TAG
  start=$(date +%s)
  echo "compose-build.sh: $2 from deploy/docker/$1"
  context_tar | DOCKER_BUILDKIT=0 "$ENGINE" build --network host --build-arg "DEBIAN=$DEBIAN_IMAGE" \
    -f "deploy/docker/$1" -t "$2" -
  echo "compose-build.sh: $2 built in $(( $(date +%s) - start )) s"
}

for what in "${@:-discovery prometheus coordinator worker}"; do
  for w in $what; do
    case "$w" in
      discovery) build Dockerfile.discovery-server poseforest-discovery ;;
      prometheus|coordinator|worker) build "Dockerfile.$w" "poseforest-$w" ;;
      *) echo "compose-build.sh: no image $w (discovery, prometheus, coordinator, worker)" >&2; exit 2 ;;
    esac
  done
done
"$ENGINE" images --format '{{.Repository}}:{{.Tag}} {{.Size}}' | grep -E '^poseforest-|^'"$DEBIAN_IMAGE"' ' || true
