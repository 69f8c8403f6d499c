#!/usr/bin/env bash
# scripts/dds-security.sh on its own (docs/security.md): what it writes, that
# the documents verify against its CA and name each certificate's subject,
# that a rerun changes nothing, that it adds participants with a CA key kept
# elsewhere, and that it refuses bad input without writing anything.
# Usage: script_test.sh SCRIPT WORKDIR
set -euo pipefail
script=$1
work=$2
rm -rf "$work"
mkdir -p "$work"
failures=0
check() {  # check DESCRIPTION COMMAND...: counts a failure when COMMAND fails
  local what=$1
  shift
  if "$@"; then echo "ok   $what"; else echo "FAIL $what"; failures=$((failures + 1)); fi
}
mode() { stat -c %a "$1"; }
signed_by_ca() { openssl verify -CAfile "$out/ca/ca.pem" "$1" >/dev/null; }
refused() {  # refused PATTERN ARGS...: exit 2, PATTERN in the message
  local pattern=$1 status=0
  shift
  "$script" "$@" >"$work/out" 2>&1 || status=$?
  [ "$status" -eq 2 ] && grep -q -- "$pattern" "$work/out" || { cat "$work/out"; return 1; }
}

out=$work/certs
"$script" "$out" >"$work/first.log"
for name in palpated pliers viewer client; do
  check "$name: key mode 0600" [ "$(mode "$out/$name/$name.key")" = 600 ]
  check "$name: certificate signed by the CA" \
    signed_by_ca "$out/$name/$name.pem"
  check "$name: permissions signed by the CA" openssl smime -verify -text -CAfile "$out/ca/ca.pem" \
    -in "$out/$name/permissions.p7s" -out "$work/$name.verified" 2>/dev/null
  # (S/MIME signs the canonical text: CRLF line ends)
  check "$name: the signed permissions are permissions.xml" \
    bash -c "tr -d '\\r' <'$work/$name.verified' | cmp -s - '$out/$name/permissions.xml'"
  subject=$(openssl x509 -in "$out/$name/$name.pem" -noout -subject -nameopt RFC2253 | sed 's/^subject=//')
  check "$name: permissions name the certificate's subject" \
    grep -qF "<subject_name>$subject</subject_name>" "$out/$name/permissions.xml"
  check "$name: its configuration names its own files" \
    grep -qF "file:$out/$name/$name.key" "$out/$name/cyclonedds.xml"
  check "$name: its configuration is loopback only" \
    grep -qF '<NetworkInterface name="lo" multicast="false"/>' "$out/$name/cyclonedds.xml"
  check "$name: its configuration is XML" /usr/bin/python3 -c \
    'import sys, xml.dom.minidom; xml.dom.minidom.parse(sys.argv[1])' "$out/$name/cyclonedds.xml"
done
check "CA key mode 0600" [ "$(mode "$out/ca/ca.key")" = 600 ]
check "governance signed by the CA" openssl smime -verify -text -CAfile "$out/ca/ca.pem" \
  -in "$out/governance.p7s" -out /dev/null 2>/dev/null
check "governance: no unauthenticated participants" \
  grep -q '<allow_unauthenticated_participants>false<' "$out/governance.xml"
check "governance: data encrypted by default" grep -q '<data_protection_kind>ENCRYPT<' "$out/governance.xml"
check "a viewer publishes nothing" bash -c "! grep -q '<publish>' '$out/viewer/permissions.xml'"
check "pliers publish poses, the end of their sessions and what they rendered only" \
  bash -c "[ \"\$(sed -n '/<publish>/,/<\/publish>/p' '$out/pliers/permissions.xml' | grep -c '<topic>')\" = 3 ] &&
           grep -q '<topic>palpate_tool_pose</topic>' '$out/pliers/permissions.xml' &&
           grep -q '<topic>palpate_tool_command</topic>' '$out/pliers/permissions.xml' &&
           grep -q '<topic>palpate_tool_rendered</topic>' '$out/pliers/permissions.xml'"
check "no temporary file left" bash -c "[ -z \"\$(find '$out' -name '.staging*' -o -name '*.tmp' -o -name '*.??????')\" ]"

# A rerun keeps every file as it is.
find "$out" -type f -exec sha256sum {} + | sort >"$work/before"
"$script" "$out" >"$work/second.log"
find "$out" -type f -exec sha256sum {} + | sort >"$work/after"
check "a rerun changes nothing" cmp -s "$work/before" "$work/after"
check "a rerun says what it kept" grep -q 'participant pliers kept' "$work/second.log"

# The CA key kept elsewhere: new participants need it, and get it with --ca-key.
mv "$out/ca/ca.key" "$work/offline.key"
check "a new participant without the CA key is refused" refused "give --ca-key" "$out" --participant pliers:station-2
check "nothing written for it" [ ! -e "$out/station-2" ]
check "a new participant with --ca-key" "$script" "$out" --participant pliers:station-2 --ca-key "$work/offline.key" \
  >"$work/third.log"
check "its certificate is signed by the same CA" \
  signed_by_ca "$out/station-2/station-2.pem"
check "another key is refused as the CA key" \
  refused "is not the key of" "$out" --participant pliers:station-3 --ca-key "$out/pliers/pliers.key"

check "--ca-key for a directory without the CA certificate is refused" \
  refused "has no CA certificate" "$work/elsewhere" --ca-key "$work/offline.key"

# Bad input: one message, exit 2, nothing written.
check "unknown kind" refused "kind 'admin' is not one of" "$work/bad" --participant admin:x
check "bad name" refused "name 'a b'" "$work/bad" --participant "pliers:a b"
check "name twice" refused "given twice" "$work/bad" --participant pliers:a --participant viewer:a
check "bad days" refused "--days 0" "$work/bad" --days 0
check "bad protection" refused "encrypt or sign" "$work/bad" --protection none
check "unknown option" refused "unknown option" "$work/bad" --force x
check "nothing written on bad input" bash -c "[ ! -e '$work/bad' ] || [ -z \"\$(ls -A '$work/bad')\" ]"
check "other governance settings refused" refused "exists with other settings" "$out" --protection sign \
  --ca-key "$work/offline.key"
check "sign protection on a new directory" "$script" "$work/signed" --protection sign --participant viewer:v \
  >"$work/fourth.log"
check "sign protection written" grep -q '<data_protection_kind>SIGN<' "$work/signed/governance.xml"

[ "$failures" -eq 0 ] || { echo "$failures check(s) failed"; exit 1; }
echo "all checks passed"
