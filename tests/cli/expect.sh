#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: expect.sh EXIT_CODE STREAM REGEX -- command...
# Runs the command and checks its exit code, and that STREAM (stdout|stderr) matches the extended REGEX,
# either on one line or with the stream's lines joined by single spaces (tools that wrap long messages).
set -u
want=$1 stream=$2 regex=$3
shift 3
[ "$1" = "--" ] && shift
out=$(mktemp) err=$(mktemp)
"$@" >"$out" 2>"$err"
got=$?
ok=1
if [ "$got" != "$want" ]; then echo "exit code $got, expected $want"; ok=0; fi
file=$out; [ "$stream" = stderr ] && file=$err
if ! grep -Eq -- "$regex" "$file" && ! tr -s ' \n' '  ' <"$file" | grep -Eq -- "$regex"; then
  echo "$stream does not match /$regex/"; ok=0
fi
if [ $ok = 0 ]; then
  echo "--- command: $*"; echo "--- stdout:"; head -40 "$out"; echo "--- stderr:"; head -40 "$err"
fi
rm -f "$out" "$err"
[ $ok = 1 ]
