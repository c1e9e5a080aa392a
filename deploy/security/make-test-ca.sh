#!/bin/sh
# make-test-ca.sh OUTDIR [NAME ...]
#
# Creates a TEST DDS-Security set-up for poseforest (Fast DDS builtin PKI-DH / Access-Permissions /
# AES-GCM-GMAC plugins) with openssl only:
#   OUTDIR/identity_ca.pem, identity_ca.key        CA that signs participant certificates
#   OUTDIR/permissions_ca.pem, permissions_ca.key  CA that signs governance and permissions
#   OUTDIR/governance.xml, governance.p7s          domain/topic protection rules (S/MIME signed)
#   OUTDIR/NAME/cert.pem, key.pem                  ECDSA P-256 identity of participant NAME
#   OUTDIR/NAME/permissions.xml, permissions.p7s   its grant (S/MIME signed)
# NAMEs default to: coordinator worker-1 worker-2. A NAME starting with "coordinator" gets the
# coordinator's grant (publish job/control/status, subscribe replies/presence); any other name
# gets a worker's grant (the reverse). Everything else is denied.
#
# For tests and trials only: the CA keys are unencrypted and sit next to the certificates. In
# production keep the CA keys offline, give each host only its own key, and rotate.
# Pitfalls (checked with Fast DDS 2.9): the CA needs keyUsage digitalSignature as well as keyCertSign
# or S/MIME verification fails; subject_name must be the RFC 2253 form of the certificate subject;
# the permission validity must contain the current date; files are given to Fast DDS as
# file:///absolute/path.
set -eu

if [ $# -lt 1 ]; then
  echo "usage: $0 OUTDIR [NAME ...]" >&2
  exit 2
fi
OUT=$1
shift
[ $# -gt 0 ] || set -- coordinator worker-1 worker-2
command -v openssl >/dev/null || { echo "$0: openssl not found (apt-get install openssl)" >&2; exit 1; }

mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
ORG=${POSEFOREST_CA_ORG:-poseforest test}
DAYS=${POSEFOREST_CA_DAYS:-3650}

make_ca() {  # name file-prefix
  openssl ecparam -name prime256v1 -genkey -noout -out "$OUT/$2.key" 2>/dev/null
  openssl req -x509 -new -key "$OUT/$2.key" -sha256 -days "$DAYS" \
    -subj "/C=ES/O=$ORG/CN=$1" \
    -addext "basicConstraints=critical,CA:true" \
    -addext "keyUsage=critical,keyCertSign,cRLSign,digitalSignature" \
    -out "$OUT/$2.pem"
}
make_ca "poseforest identity CA" identity_ca
make_ca "poseforest permissions CA" permissions_ca

sign() {  # in.xml out.p7s
  openssl smime -sign -in "$1" -text -out "$2" \
    -signer "$OUT/permissions_ca.pem" -inkey "$OUT/permissions_ca.key"
}

cat > "$OUT/governance.xml" <<'XML'
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>0</min><max>232</max></id_range></domains>
      <!-- Only authenticated participants with a valid grant join. -->
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>poseforest/*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <!-- Payload encryption only (~0.5 ms/MiB per side); histograms and forests are
               protected, sample metadata is not (see docs/distributed/README.md). -->
          <metadata_protection_kind>NONE</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
sign "$OUT/governance.xml" "$OUT/governance.p7s"

topics() { for t in "$@"; do printf '<topic>poseforest/%s</topic>' "$t"; done; }

for NAME in "$@"; do
  D="$OUT/$NAME"
  mkdir -p "$D"
  openssl ecparam -name prime256v1 -genkey -noout -out "$D/key.pem" 2>/dev/null
  openssl req -new -key "$D/key.pem" -subj "/C=ES/O=$ORG/CN=$NAME" -out "$D/cert.csr"
  openssl x509 -req -in "$D/cert.csr" -CA "$OUT/identity_ca.pem" -CAkey "$OUT/identity_ca.key" \
    -CAcreateserial -days "$DAYS" -sha256 -out "$D/cert.pem" 2>/dev/null
  rm -f "$D/cert.csr"
  SUBJECT=$(openssl x509 -noout -subject -nameopt RFC2253 -in "$D/cert.pem" | sed 's/^subject=//')
  case "$NAME" in
    coordinator*) PUB=$(topics job control status); SUB=$(topics replies presence) ;;
    *)            PUB=$(topics replies presence);   SUB=$(topics job control status) ;;
  esac
  cat > "$D/permissions.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$NAME">
      <subject_name>$SUBJECT</subject_name>
      <validity><not_before>2020-01-01T00:00:00</not_before><not_after>2045-01-01T00:00:00</not_after></validity>
      <allow_rule>
        <domains><id_range><min>0</min><max>232</max></id_range></domains>
        <publish><topics>$PUB</topics></publish>
        <subscribe><topics>$SUB</topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
XML
  sign "$D/permissions.xml" "$D/permissions.p7s"
done
rm -f "$OUT"/*.srl
echo "test CA and credentials for: $* -> $OUT"
