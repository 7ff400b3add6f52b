#!/usr/bin/env bash
# The carries a GPU device session needs, cut to fit: ../shared/tools/device-wheels
# builds the MuJoCo / MJX / warp-lang bundle in two halves (.dw-a, .dw-b) of ~61 MB
# each, but a call carries the working tree too (~12 MB) under one 64 MiB limit, so a
# half no longer travels. This re-cuts the bundle into three thirds, staged in three
# calls made back to back (the machine stays warm ~30 s after each):
#
#   bash tools/device_bundle.sh
#   call 1: carry [".dw-a"]  command: bash .dw-a/stage.sh
#   call 2: carry [".dw-c"]  command: bash .dw-c/stage.sh
#   call 3: carry [".dw-b"]  command: bash .dw-b/stage.sh && export PYTHONPATH=/tmp/site && ...
#   later calls (warm):      command: bash .dw-b/stage.sh project && export PYTHONPATH=/tmp/site && ...
#
# It also adds what the project imports and the device image lacks (EXTRAS; found
# missing there: platformdirs, the object cache's folder; rtree, which trimesh needs
# to nest a mesh section's polygons). Check the device's time left (status) before
# the first call: the three calls and the install take about a minute.
set -euo pipefail
EXTRAS=${EXTRAS:-"platformdirs rtree"}
cd "$(dirname "$0")/.."
shared=${SHARED_TOOLS:-../shared/tools}
# shellcheck disable=SC2086
"$shared/device-wheels" $EXTRAS
grep -qx "/.dw-c/" .git/info/exclude || echo "/.dw-c/" >> .git/info/exclude
tmp=$(mktemp -d)
cat .dw-a/bundle.part00 .dw-b/bundle.part01 > "$tmp/bundle"
rm -f .dw-a/bundle.part00 .dw-b/bundle.part01
rm -rf .dw-c && mkdir -p .dw-c
split -n 3 -d -a 2 "$tmp/bundle" "$tmp/part"
mv "$tmp/part00" .dw-a/bundle.part00
mv "$tmp/part01" .dw-c/bundle.part01
mv "$tmp/part02" .dw-b/bundle.part02
rm -rf "$tmp"
cat > .dw-c/stage.sh <<'EOF'
#!/usr/bin/env bash
# call 2 (between .dw-a's and .dw-b's): keep the bundle's second third in /tmp
set -e; here=$(cd "$(dirname "$0")" && pwd)
mkdir -p /tmp/stage && cp "$here/bundle.part01" /tmp/stage/ && echo "second third staged"
EOF
# .dw-b joins all three thirds (device-wheels' script joins two halves)
sed -i \
  -e 's#\[ -f /tmp/stage/bundle.part00 \]#[ -f /tmp/stage/bundle.part00 ] \&\& [ -f /tmp/stage/bundle.part01 ]#' \
  -e 's#cat /tmp/stage/bundle.part00 "$here/bundle.part01"#cat /tmp/stage/bundle.part00 /tmp/stage/bundle.part01 "$here/bundle.part02"#' \
  -e 's#half A missing: the machine went cold; repeat call A, then B#a third is missing: the machine went cold; repeat the calls of .dw-a, .dw-c, .dw-b#' \
  .dw-b/stage.sh
grep -q "bundle.part02" .dw-b/stage.sh || { echo "device-wheels' stage.sh changed: .dw-b not re-cut" >&2; exit 1; }
tree_mb=$(git ls-files -z | xargs -0 du -cb | tail -1 | cut -f1)
for d in .dw-a .dw-c .dw-b; do
  mb=$(( ($(du -sb "$d" | cut -f1) + tree_mb) / 1048576 ))
  echo "$d with the tree: ${mb} MiB (limit 64)"
done
