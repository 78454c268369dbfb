#!/usr/bin/env bash
# Sets up the browser client and its test tooling (no network at page run time):
#  1. npm ci in tests/e2e (playwright-core, pngjs, protobufjs, and @playcanvas/splat-transform 2.7.1,
#     the scene formats' reference in the unit tests; versions pinned by package-lock.json),
#  2. vendors protobufjs's browser build into web_client/viewer/vendor/ (BSD-3-Clause, licence copied along),
#  3. copies proto/catgs_stream.proto into web_client/viewer/ (the viewer library loads the schema at run time) and
#     writes its JSON descriptor beside it (a fallback for static servers that refuse .proto);
#     both are generated, not committed (.gitignore).
# Idempotent; run it after cloning and whenever proto/ or tests/e2e/package-lock.json changes.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
e2e="$root/tests/e2e"
web="$root/web_client/viewer"

if ! command -v npm >/dev/null; then
  echo "setup_web.sh: npm is missing (apt-get install nodejs npm)" >&2
  exit 1
fi
# protobufjs's postinstall only checks optional CLI deps; nothing here needs install scripts.
(cd "$e2e" && npm ci --no-audit --no-fund --ignore-scripts)
# The Kubernetes manifests' offline schema check (tests/deploy, pinned by its package-lock.json).
(cd "$root/tests/deploy" && npm ci --no-audit --no-fund --ignore-scripts)

mkdir -p "$web/vendor"
cp "$e2e/node_modules/protobufjs/dist/protobuf.min.js" "$web/vendor/protobuf.min.js"
cp "$e2e/node_modules/protobufjs/LICENSE" "$web/vendor/LICENSE.protobufjs"

cp "$root/proto/catgs_stream.proto" "$web/catgs_stream.proto"
(cd "$e2e" && node --input-type=module -e '
  import pb from "protobufjs";
  import { readFileSync, writeFileSync } from "node:fs";
  const [src, dst] = process.argv.slice(1);
  // Parsed exactly as the page parses the .proto (field names kept as written).
  const root = pb.parse(readFileSync(src, "utf8"), { keepCase: true }).root;
  writeFileSync(dst, JSON.stringify(root.toJSON(), null, 1) + "\n");
' "$root/proto/catgs_stream.proto" "$web/catgs_stream.json")
echo "setup_web.sh: web client ready (web_client/viewer/: vendor/protobuf.min.js, catgs_stream.proto, catgs_stream.json)"
