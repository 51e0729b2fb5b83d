#!/usr/bin/env bash
# make test-gui: the built extension in a real Blender window (Debian's blender from sid, in a throw-away chroot
# made with debootstrap, under Xvfb), as tests/gui/smoke.py drives it; then the checks: the run finished and its
# result object exists, the GT² tab was open, no Python error in the console. Screenshots: $OUT (docs/ with
# GUI_DOCS=1). Needs root (debootstrap, chroot, bind mounts) and Debian's package mirror; several minutes.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
WORK="$(cd "$ROOT/.." && pwd)"
CHROOT="${GT2GS_GUI_CHROOT:-/var/tmp/gt2gs-sid}"
OUT="${OUT:-$ROOT/out/gui}"
PY="${PY:-$ROOT/.venv/bin/python}"
MIRROR=http://deb.debian.org/debian
PACKAGES="blender xvfb imagemagick python3-numpy python3-attr python3-requests python3-zstandard python3-typing-extensions"

if [ ! -x "$CHROOT/usr/bin/blender" ]; then
  command -v debootstrap >/dev/null || apt-get install -y -q debootstrap
  # debootstrap's --include leaves blender unconfigured (a virtual OpenEXR dependency): apt installs it inside.
  debootstrap --variant=minbase sid "$CHROOT" "$MIRROR"
  chroot "$CHROOT" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin DEBIAN_FRONTEND=noninteractive \
    apt-get install -y -q --no-install-recommends $PACKAGES
fi
# Blender's extension system needs cattrs, which Debian does not package: the pure-Python one from .venv313.
SITE="$CHROOT/usr/local/lib/$(basename "$(ls -d "$CHROOT"/usr/lib/python3.*/ | sort -V | tail -n 1)")/dist-packages"
if [ ! -d "$SITE/cattrs" ]; then
  mkdir -p "$SITE"
  cp -r "$ROOT"/.venv313/lib/python3.*/site-packages/{cattrs,cattr} "$SITE"/
fi

make -C "$ROOT" -s build STAMP= PY="$PY"
ZIP="$(ls "$ROOT"/dist/gt2gs_blender-*.zip)"
mkdir -p "$OUT"

mounts=()
cleanup() {
  # $! is the subshell running in_chroot, not Xvfb: its own lock file names it.
  [ -f "$CHROOT/tmp/.X99-lock" ] && kill "$(tr -d ' ' <"$CHROOT/tmp/.X99-lock")" 2>/dev/null || true
  for ((i = ${#mounts[@]} - 1; i >= 0; i--)); do umount "${mounts[$i]}" 2>/dev/null || true; done
}
trap cleanup EXIT
bind() { mkdir -p "$CHROOT$1" && mount --bind "$1" "$CHROOT$1" && mounts+=("$CHROOT$1"); }
bind /proc
bind /dev
bind "$WORK"
# The worker's Python (the project's .venv) and what it links to.
PYREAL="$(readlink -f "$PY")"
bind "$(dirname "$(dirname "$PYREAL")")"

in_chroot() {
  chroot "$CHROOT" /usr/bin/env -i PATH=/usr/bin:/bin HOME=/root DISPLAY=:99 LANG=C.UTF-8 \
    GT2GS_WORKER_PYTHON="$PY" GT2GS_WEIGHTS_DIR="$WORK/shared/weights" "$@"
}
in_chroot Xvfb :99 -screen 0 1600x900x24 -nolisten tcp >"$OUT/xvfb.log" 2>&1 &
sleep 3
in_chroot blender --command extension install-file -r user_default -e "$ZIP" >"$OUT/install.log" 2>&1
# A file given on the command line opens without the splash screen over the view: the default scene, no cube.
in_chroot blender -b --python-expr "import bpy; bpy.data.objects.remove(bpy.data.objects['Cube']); \
bpy.ops.wm.save_as_mainfile(filepath='$OUT/start.blend')" >"$OUT/start.log" 2>&1
in_chroot blender "$OUT/start.blend" --python "$ROOT/tests/gui/smoke.py" -- "$OUT" >"$OUT/console.log" 2>&1 || true

python3 - "$OUT" <<'EOF'
import json, re, sys
from pathlib import Path
out = Path(sys.argv[1])
found = json.loads((out / "smoke.json").read_text())
console = (out / "console.log").read_text(errors="replace")
problems = [f"smoke: {found['error']}"] if found.get("error") else []
problems += [f"console: {line}" for line in console.splitlines() if re.match(r"(Traceback|\w*Error\b)", line)]
if found.get("tab") != "GT²":
    problems.append(f"the GT² tab was not open: {found.get('tab')!r}")
outcome = found.get("outcome") or {}
if outcome.get("state") != "DONE" or not found.get("result_exists"):
    problems.append(f"the transfer did not leave its result: {outcome}")
for name in ("gui_idle_panel.png", "gui_finished_run.png"):
    if not (out / name).is_file():
        problems.append(f"no screenshot {name}")
print(json.dumps(found, indent=1))
if problems:
    sys.exit("make test-gui failed:\n" + "\n".join(problems))
print(f"make test-gui passed: {found['blender']} (Python {found['python']}), {outcome['message']}")
EOF
if [ "${GUI_DOCS:-0}" = 1 ]; then
  for name in gui_idle_panel gui_finished_run; do
    "$PY" -c "import cv2, sys; cv2.imwrite(sys.argv[2], cv2.imread(sys.argv[1]), [cv2.IMWRITE_JPEG_QUALITY, 85])" \
      "$OUT/$name.png" "$ROOT/docs/$name.jpg"
  done
fi
