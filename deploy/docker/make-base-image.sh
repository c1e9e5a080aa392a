#!/bin/sh
# Builds the Debian 12 base image the Dockerfiles start from (`ARG DEBIAN=debian:12`) out of
# Debian packages alone, for machines that reach Debian's mirror but no image registry:
# `debootstrap --variant=minbase bookworm` into a temporary root, the apt sources of bookworm,
# bookworm-updates and bookworm-security, then `docker import` (or `podman import`) as TAG.
#
#   deploy/docker/make-base-image.sh [TAG]          # TAG: debian:12 (default)
#   ENGINE=podman deploy/docker/make-base-image.sh  # podman instead of docker
#   MIRROR=http://deb.example.org/debian ...        # another Debian mirror (default deb.debian.org)
#
# Needs root (debootstrap makes device nodes and chroots) and Debian's `debootstrap` package.
# Nothing but the mirror is contacted. With TAG debian:12 the Dockerfiles and deploy/compose.yaml
# build unchanged; with another TAG pass `--build-arg DEBIAN=TAG` (compose: POSEFOREST_DEBIAN=TAG).
# About 2 min and 120 MB on a 2-core machine (docs/distributed/compose.md).
set -eu

TAG=${1:-debian:12}
ENGINE=${ENGINE:-docker}
MIRROR=${MIRROR:-http://deb.debian.org/debian}
SECURITY_MIRROR=${SECURITY_MIRROR:-$(echo "$MIRROR" | sed 's,/debian$,/debian-security,')}

if [ "$(id -u)" != 0 ]; then
  echo "make-base-image.sh: run as root (debootstrap needs it)" >&2
  exit 2
fi
command -v debootstrap >/dev/null || { echo "make-base-image.sh: apt-get install debootstrap" >&2; exit 2; }
command -v "$ENGINE" >/dev/null || { echo "make-base-image.sh: $ENGINE is not on PATH" >&2; exit 2; }

work=$(mktemp -d /tmp/pf-base-image.XXXXXX)
trap 'rm -rf "$work"' EXIT INT TERM
root=$work/rootfs

debootstrap --variant=minbase bookworm "$root" "$MIRROR"

# The same sources as Debian's own image, so `apt-get install` in a Dockerfile sees security updates.
rm -f "$root/etc/apt/sources.list"
cat > "$root/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $MIRROR
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: $SECURITY_MIRROR
Suites: bookworm-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
# As in Debian's image: packages installed in a build never start their services (policy-rc.d
# says 101, e.g. prometheus's init script), no recommends by accident, no package caches, no host
# name of this machine.
printf '#!/bin/sh\nexit 101\n' > "$root/usr/sbin/policy-rc.d"
chmod 755 "$root/usr/sbin/policy-rc.d"
printf 'APT::Install-Recommends "false";\n' > "$root/etc/apt/apt.conf.d/90poseforest-norecommends"
chroot "$root" apt-get clean
rm -rf "$root"/var/lib/apt/lists/* "$root"/var/cache/apt/*.bin "$root"/tmp/* "$root"/var/log/*.log
: > "$root/etc/hostname"
: > "$root/etc/resolv.conf"

tar -C "$root" --numeric-owner -c . |
  "$ENGINE" import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["bash"]' \
    - "$TAG"
echo "make-base-image.sh: $TAG ($("$ENGINE" image inspect --format '{{.Size}}' "$TAG") bytes)"
