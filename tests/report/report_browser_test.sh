#!/usr/bin/env bash
# ctest driver of the browser test: a short room run that still closes a loop (every 3rd frame of
# the first 375, one loop closure), a detect run on a simulated depth image, then both reports
# loaded in headless Chromium (report_browser_test.mjs). Exit 77 (skipped) without chromium,
# without web/node_modules or when planeslam was built without the page.
#   report_browser_test.sh PLANESLAM_BIN WORK_DIR
set -euo pipefail
bin=$1
work=$2
here=$(cd "$(dirname "$0")" && pwd)
chromium=${PLANESLAM_CHROMIUM:-/usr/bin/chromium}
if [ ! -x "$chromium" ]; then
  echo "SKIP: $chromium not found (Debian package chromium; 'make deps' installs it)"; exit 77
fi
if ! command -v node >/dev/null; then echo "SKIP: node not found (Debian package nodejs)"; exit 77; fi
if [ ! -d "$here/../../web/node_modules/playwright-core" ]; then
  echo "SKIP: web/node_modules absent (run 'npm ci --prefix web')"; exit 77
fi
rm -rf "$work"
mkdir -p "$work"
"$bin" run --quiet -o "$work/run" --set run.frame_stride=3 --set run.max_frames=125 \
  --set octomap.enabled=false > "$work/run.log" 2> "$work/run.err"
if grep -q "built without web/node_modules" "$work/run.err"; then
  echo "SKIP: planeslam was built without the report page (web/node_modules absent at configure)"; exit 77
fi
"$bin" simulate room --quiet --frames 1 -o "$work/sim" > /dev/null
"$bin" detect "$(ls "$work"/sim/depth/*.png | head -1)" --quiet -o "$work/detect"
node "$here/report_browser_test.mjs" --run "$work/run" --detect "$work/detect"
