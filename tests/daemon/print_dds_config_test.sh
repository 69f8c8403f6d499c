#!/bin/sh
# palpated --print-dds-config prints palpate's loopback configuration
# (config/dds-loopback.xml) when the user gives none, the user's otherwise.
# No DDS participant is created.
# Usage: print_dds_config_test.sh PALPATED SOURCE_DIR
set -eu
palpated=$1 source_dir=$2
expected=$(cat "$source_dir/config/dds-loopback.xml")
got=$(env -u CYCLONEDDS_URI "$palpated" --print-dds-config)
[ "$got" = "$expected" ] || { echo "FAIL: built-in configuration: got '$got'" >&2; exit 1; }
case $got in *'<AllowMulticast>false</AllowMulticast>'*) ;; *) echo "FAIL: multicast not off" >&2; exit 1 ;; esac
got=$(CYCLONEDDS_URI='<General/>' "$palpated" --print-dds-config)
[ "$got" = '<General/>' ] || { echo "FAIL: CYCLONEDDS_URI not used: got '$got'" >&2; exit 1; }
got=$(CYCLONEDDS_URI='<General/>' "$palpated" --dds-config '<Discovery/>' --print-dds-config)
[ "$got" = '<Discovery/>' ] || { echo "FAIL: --dds-config not used: got '$got'" >&2; exit 1; }
echo "print_dds_config: built-in, CYCLONEDDS_URI and --dds-config as documented"
