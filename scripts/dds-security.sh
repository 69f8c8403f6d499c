#!/usr/bin/env bash
# Creates what palpate needs to run with DDS Security (docs/security.md):
# a certificate authority, one identity (key + certificate) per participant,
# the governance document, one permissions document per participant, both
# signed by the CA, and one Cyclone DDS configuration per participant to give
# to its program with --dds-config (or dds.config for palpated).
#
# Usage: scripts/dds-security.sh OUTDIR [--participant KIND:NAME]... [options]
#   KIND     daemon   palpated: reads requests and poses, writes everything else
#            pliers   palpate-pliers, a haptic device: writes poses, reads models, feedback,
#                     events and status (whether palpated is there)
#            viewer   palpate-viewer: reads models, the surface stream, status and the tool topics
#            client   palpate-client, batch or scripted clients: writes requests, reads its
#                     replies, models, the surface stream and status
#   NAME     [A-Za-z0-9_.-], 1 to 63 characters, unique (OUTDIR/NAME/ holds its files)
#   Without --participant: daemon:palpated pliers:pliers viewer:viewer client:client.
# Options:
#   --days N             validity of new certificates and permissions (default 365)
#   --domain D           the DDS domain (palpated's dds.domain) they are valid in (default 0)
#   --protection P       how data on palpate's topics is protected: encrypt (default) or sign
#   --ca-key FILE        the CA's private key when it is kept elsewhere (default OUTDIR/ca/ca.key)
#
# What it writes (private keys mode 0600, every file written atomically):
#   OUTDIR/ca/ca.pem, ca.key        the CA (identity and permissions CA): ECDSA P-256, 10 years
#   OUTDIR/governance.xml, .p7s     the domain's rules, signed (S/MIME) by the CA
#   OUTDIR/NAME/NAME.pem, NAME.key  the participant's identity, signed by the CA
#   OUTDIR/NAME/permissions.xml, .p7s
#   OUTDIR/NAME/cyclonedds.xml      palpate's loopback-only configuration plus <Security>
# It never overwrites: an existing CA is reused to sign new participants, an
# existing participant or governance is kept (delete OUTDIR/NAME to reissue
# it). Run it again with more --participant to add participants; keep the CA
# key offline between runs (--ca-key). Exit codes: 0 done, 2 bad usage or
# refused, 1 a tool (openssl) failed.
set -euo pipefail

fail() { echo "dds-security: $*" >&2; exit 2; }
# palpate's built-in loopback configuration (docs/dds.md, "Network
# configuration"), the same file the library is built with.
loopback_xml=$(dirname "$(realpath "$0")")/../config/dds-loopback.xml
[ -r "$loopback_xml" ] || { echo "dds-security: $loopback_xml is missing: run this script from a palpate checkout" >&2; exit 1; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//' >&2; exit 2; }

[ $# -ge 1 ] || usage
case $1 in -h | --help) usage ;; -*) fail "the first argument is the output directory, got '$1'" ;; esac
outdir=$1
shift
participants=()
days=365
domain=0
protection=encrypt
ca_key=
while [ $# -gt 0 ]; do
  [ $# -ge 2 ] || fail "$1 needs a value (--help for usage)"
  case $1 in
    --participant) participants+=("$2") ;;
    --days) days=$2 ;;
    --domain) domain=$2 ;;
    --protection) protection=$2 ;;
    --ca-key) ca_key=$2 ;;
    *) fail "unknown option '$1'; accepted: --participant KIND:NAME, --days N, --domain D, --protection encrypt|sign, --ca-key FILE" ;;
  esac
  shift 2
done
[ ${#participants[@]} -gt 0 ] || participants=(daemon:palpated pliers:pliers viewer:viewer client:client)
[[ $days =~ ^[0-9]+$ ]] && [ "$days" -ge 1 ] && [ "$days" -le 36500 ] ||
  fail "--days $days: a whole number of days, 1 to 36500"
[[ $domain =~ ^[0-9]+$ ]] && [ "$domain" -le 232 ] || fail "--domain $domain: a DDS domain id, 0 to 232"
case $protection in
  encrypt) data_kind=ENCRYPT ;;
  sign) data_kind=SIGN ;;
  *) fail "--protection $protection: encrypt or sign" ;;
esac
command -v openssl >/dev/null || fail "openssl is missing (Debian package openssl; scripts/install-deps.sh)"

# Debian installs Cyclone's plugins outside the library search path, in a
# directory its libddsc searches by itself for a plugin given by name
# ("dds_security_auth" → <that directory>/libdds_security_auth.so): the
# configurations name them so, valid on any Debian architecture.
plugin_dir=
for d in /usr/lib/*/libddsc0debian /usr/lib/libddsc0debian; do
  [ -f "$d/libdds_security_auth.so" ] && plugin_dir=$d && break
done
[ -n "$plugin_dir" ] || fail "Cyclone DDS's security plugins (libdds_security_auth.so) are not installed (Debian package libddsc0debian)"

declare -A seen=()
for p in "${participants[@]}"; do
  kind=${p%%:*} name=${p#*:}
  [[ $p == *:* ]] || fail "--participant $p: expected KIND:NAME, e.g. pliers:left-station"
  case $kind in daemon | pliers | viewer | client) ;; *)
    fail "--participant $p: kind '$kind' is not one of daemon, pliers, viewer, client" ;;
  esac
  [[ $name =~ ^[A-Za-z0-9_.-]{1,63}$ ]] && [ "$name" != ca ] && [[ $name != .* ]] ||
    fail "--participant $p: name '$name': 1 to 63 of [A-Za-z0-9_.-], not starting with '.', not 'ca'"
  [ -z "${seen[$name]:-}" ] || fail "--participant $p: name '$name' given twice"
  seen[$name]=1
done

outdir=$(realpath -m "$outdir")
# Cyclone takes these paths in file: URIs inside XML: keep them plain.
[[ $outdir =~ ^[A-Za-z0-9_./+-]+$ ]] ||
  fail "output directory '$outdir': its path may hold only letters, digits and _ . / + - (it goes into file: URIs)"
mkdir -p "$outdir"

umask 077
staging=$(mktemp -d "$outdir/.staging.XXXXXX")
trap 'rm -rf "$staging"' EXIT
# write FILE: stdin to FILE, atomically (a reader sees the old file or the whole new one).
write() {
  local tmp
  tmp=$(mktemp "$1.XXXXXX")
  cat >"$tmp"
  chmod 0644 "$tmp"
  mv -f "$tmp" "$1"
}
ossl() { openssl "$@" 2>"$staging/openssl.log" || { cat "$staging/openssl.log" >&2; echo "dds-security: openssl $1 failed" >&2; exit 1; }; }
utc() { date -u -d "@$1" +%Y-%m-%dT%H:%M:%SZ; }

# --------------------------------------------------------------------- the CA
ca_dir=$outdir/ca
ca_cert=$ca_dir/ca.pem
: "${ca_key:=$ca_dir/ca.key}"
if [ ! -e "$ca_cert" ]; then
  [ "$ca_key" = "$ca_dir/ca.key" ] ||
    fail "--ca-key $ca_key: $outdir has no CA certificate (ca/ca.pem); copy the CA's ca.pem there first"
  [ ! -e "$ca_dir" ] || fail "$ca_dir exists without ca.pem: restore the certificate, or remove $ca_dir to start a new CA"
  mkdir -p "$staging/ca"
  ossl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$staging/ca/ca.key"
  ossl req -new -x509 -sha256 -days 3650 -key "$staging/ca/ca.key" -out "$staging/ca/ca.pem" \
    -subj "/O=palpate/CN=palpate DDS CA" -addext "basicConstraints=critical,CA:TRUE" \
    -addext "keyUsage=critical,keyCertSign,cRLSign,digitalSignature"
  chmod 0600 "$staging/ca/ca.key"
  chmod 0644 "$staging/ca/ca.pem"
  chmod 0755 "$staging/ca"
  mv -T "$staging/ca" "$ca_dir"  # one rename: the CA is there whole or not at all
  echo "dds-security: new CA $ca_cert (key $ca_dir/ca.key, mode 0600: keep it offline, docs/security.md)"
else
  echo "dds-security: CA $ca_cert kept"
fi
need_ca_key() {
  [ -r "$ca_key" ] || fail "signing needs the CA's key: $ca_key is not readable (give --ca-key FILE)"
  openssl x509 -in "$ca_cert" -noout -pubkey >"$staging/ca.pub" 2>/dev/null &&
    openssl pkey -in "$ca_key" -pubout >"$staging/key.pub" 2>/dev/null &&
    cmp -s "$staging/ca.pub" "$staging/key.pub" || fail "$ca_key is not the key of $ca_cert"
}
sign() {  # sign XML P7S: S/MIME, clear text, signed by the CA (what Cyclone's access control reads)
  need_ca_key
  ossl smime -sign -text -in "$1" -out "$2.tmp" -signer "$ca_cert" -inkey "$ca_key"
  chmod 0644 "$2.tmp"
  mv -f "$2.tmp" "$2"
}

# ------------------------------------------------------------- the governance
# Every participant must authenticate (no unauthenticated participant, join
# access control) and every topic is read- and write-controlled by the
# permissions. Discovery and liveliness are encrypted (secure built-in
# endpoints, a one-off cost at join). The messages are signed (RTPS
# protection: an outsider cannot inject or replay submessages, heartbeats or
# acknacks included); the samples' payload is encrypted or signed
# (--protection: AES-GCM or GMAC, the same one pass over the payload, so
# encrypt costs about what sign does, docs/benchmarks-history.md "Secured").
governance_xml() {
  cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- palpate's DDS Security governance: written by scripts/dds-security.sh (docs/security.md) -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>
        <id>$domain</id>
      </domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>palpate_*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>NONE</metadata_protection_kind>
          <data_protection_kind>$data_kind</data_protection_kind>
        </topic_rule>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>NONE</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF
}
governance_xml >"$staging/governance.xml"
if [ -e "$outdir/governance.p7s" ]; then
  cmp -s "$staging/governance.xml" "$outdir/governance.xml" ||
    fail "$outdir/governance.xml exists with other settings (domain, protection) than asked; remove governance.xml and governance.p7s to change them (then restart every participant)"
  echo "dds-security: governance $outdir/governance.p7s kept"
else
  sign "$staging/governance.xml" "$staging/governance.p7s"
  write "$outdir/governance.xml" <"$staging/governance.xml"
  mv -f "$staging/governance.p7s" "$outdir/governance.p7s"
  echo "dds-security: governance $outdir/governance.p7s (domain $domain, data $data_kind)"
fi

# ---------------------------------------------------------- the participants
# rule TOPIC [PARTITION]: one <topic> in the default partition (no
# <partitions>), or in the partitions matching PARTITION.
topics() {
  local t
  echo "          <topics>"
  for t in "$@"; do echo "            <topic>$t</topic>"; done
  echo "          </topics>"
}
reply_partition() {
  echo "          <partitions>"
  echo "            <partition>palpate.client.*</partition>"
  echo "          </partitions>"
}
tool_partition() {
  echo "          <partitions>"
  echo "            <partition>palpate.tool.*</partition>"
  echo "          </partitions>"
}
publish() { echo "        <publish>"; topics "$@"; echo "        </publish>"; }
subscribe() { echo "        <subscribe>"; topics "$@"; echo "        </subscribe>"; }
# What each kind may do (docs/security.md, "Who may do what"); palpate_reply
# lives in the partitions palpate.client.<client id>, palpate_tool_response
# (and a copy of each palpate_tool_event) in palpate.tool.<tool id>.
kind_rules() {
  case $1 in
    daemon)
      publish palpate_model palpate_surface palpate_status palpate_tool_feedback palpate_tool_event \
        palpate_tool_notice
      { echo "        <publish>"; topics palpate_reply; reply_partition; echo "        </publish>"; }
      { echo "        <publish>"; topics palpate_tool_response palpate_tool_event; tool_partition
        echo "        </publish>"; }
      subscribe palpate_request palpate_tool_pose palpate_tool_command palpate_tool_rendered ;;
    pliers)
      publish palpate_tool_pose palpate_tool_command palpate_tool_rendered
      subscribe palpate_model palpate_status palpate_tool_feedback palpate_tool_event \
        palpate_tool_notice
      { echo "        <subscribe>"; topics palpate_tool_response palpate_tool_event; tool_partition
        echo "        </subscribe>"; } ;;
    viewer)
      subscribe palpate_model palpate_surface palpate_status palpate_tool_pose palpate_tool_feedback \
        palpate_tool_event ;;
    client)
      publish palpate_request
      subscribe palpate_model palpate_surface palpate_status
      { echo "        <subscribe>"; topics palpate_reply; reply_partition; echo "        </subscribe>"; } ;;
  esac
}
permissions_xml() {  # KIND NAME SUBJECT NOT_BEFORE NOT_AFTER
  cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- palpate participant $2 ($1): written by scripts/dds-security.sh (docs/security.md) -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$2">
      <subject_name>$3</subject_name>
      <validity>
        <not_before>$4</not_before>
        <not_after>$5</not_after>
      </validity>
      <allow_rule>
        <domains>
          <id>$domain</id>
        </domains>
$(kind_rules "$1")
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
EOF
}
cyclone_xml() {  # KIND NAME
  local dir=$outdir/$2
  cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- palpate participant $2 ($1), secured: written by scripts/dds-security.sh (docs/security.md).
     Loopback only, as palpate's built-in configuration (docs/dds.md, "Network configuration"). -->
<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    $(cat "$loopback_xml")
    <Security>
      <Authentication>
        <Library path="dds_security_auth" initFunction="init_authentication" finalizeFunction="finalize_authentication"/>
        <IdentityCA>file:$ca_cert</IdentityCA>
        <IdentityCertificate>file:$dir/$2.pem</IdentityCertificate>
        <PrivateKey>file:$dir/$2.key</PrivateKey>
      </Authentication>
      <AccessControl>
        <Library path="dds_security_ac" initFunction="init_access_control" finalizeFunction="finalize_access_control"/>
        <PermissionsCA>file:$ca_cert</PermissionsCA>
        <Governance>file:$outdir/governance.p7s</Governance>
        <Permissions>file:$dir/permissions.p7s</Permissions>
      </AccessControl>
      <Cryptographic>
        <Library path="dds_security_crypto" initFunction="init_crypto" finalizeFunction="finalize_crypto"/>
      </Cryptographic>
    </Security>
  </Domain>
</CycloneDDS>
EOF
}

for p in "${participants[@]}"; do
  kind=${p%%:*} name=${p#*:}
  if [ -e "$outdir/$name" ]; then
    echo "dds-security: participant $name kept ($outdir/$name exists; delete it to reissue)"
    continue
  fi
  need_ca_key
  s=$staging/$name
  mkdir -p "$s"
  ossl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$s/$name.key"
  chmod 0600 "$s/$name.key"
  ossl req -new -key "$s/$name.key" -subj "/O=palpate/OU=$kind/CN=$name" -out "$s/$name.csr"
  now=$(date -u +%s)
  ossl x509 -req -sha256 -in "$s/$name.csr" -CA "$ca_cert" -CAkey "$ca_key" -CAcreateserial \
    -CAserial "$staging/ca.srl" -days "$days" -out "$s/$name.pem" \
    -extfile <(printf 'basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n')
  rm -f "$s/$name.csr"
  chmod 0644 "$s/$name.pem"
  subject=$(openssl x509 -in "$s/$name.pem" -noout -subject -nameopt RFC2253 | sed 's/^subject=//')
  permissions_xml "$kind" "$name" "$subject" "$(utc "$now")" "$(utc $((now + days * 86400)))" \
    >"$s/permissions.xml"
  sign "$s/permissions.xml" "$s/permissions.p7s"
  cyclone_xml "$kind" "$name" >"$s/cyclonedds.xml"
  chmod 0644 "$s/permissions.xml" "$s/cyclonedds.xml"
  chmod 0755 "$s"
  mv -T "$s" "$outdir/$name"  # one rename: the participant is there whole or not at all
  echo "dds-security: participant $name ($kind): --dds-config $outdir/$name/cyclonedds.xml (valid $days days)"
done
