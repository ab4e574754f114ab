#!/usr/bin/env bash
# The ROS 2 tools of the development environment, built into .venv (issues 14.1, 11.4).
#
#   tools/ros_tools.sh [VENV]      (./dev calls it when its inputs changed)
#
# From the vendored, unmodified sources in $GRIP_FORCE_VENDOR (default ../shared/vendor
# beside the repository; see its README.md), copied to VENV/ros/src first:
#   - ros2cli (ros2cli, ros2pkg, ros2run, ros2node, ros2service, ros2param, ros2topic,
#     ros2interface, ros2lifecycle, ros2action), rosidl_runtime_py, launch, launch_xml,
#     launch_yaml, launch_ros, ros2launch: pip install --no-deps --no-build-isolation into VENV
#     (--no-deps: PyPI has an unrelated package named `launch`);
#   - composition_interfaces (launch_ros imports it; no wheel): plain cmake into VENV;
#   - crtk_msgs (unless it is importable already, as on a ROS machine): colcon, into
#     VENV/ros/install, with a generated rclcpp stub (its CMakeLists asks for rclcpp, which
#     messages do not need and which has no wheel);
#   - control_msgs (GripperCommand, ParallelGripperCommand; unless importable already):
#     cmake with the ament/rosidl wheels, as crtk_msgs, into VENV's prefix (several
#     minutes on two cores: its stamp keeps it until its sources or the pins change);
#   - the CRTK and dVRK Python clients (crtk, dvrk): pip install --no-deps, with PyKDL from
#     Debian's python3-pykdl + liborocos-kdl1.5 unpacked into VENV/ros/pykdl;
#   - this package: colcon build --symlink-install into VENV/ros/install, so that
#     `ros2 run grip_force_ros controller` finds lib/grip_force_ros/controller through the
#     ament index and source edits are live.
# Then it writes VENV/ros_setup.bash, the one file to source. Each step keeps a stamp of its
# inputs in VENV/ros/stamps and is redone only when they change. Without the vendored
# sources it writes why to VENV/ros_tools.status, prints one line and succeeds: the demo and
# the tests that do not need these tools work without them.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
venv=$(cd "${1:-$root/.venv}" && pwd)
vendor=${GRIP_FORCE_VENDOR:-$root/../shared/vendor}
py=$venv/bin/python
ros=$venv/ros
status=$venv/ros_tools.status
setup_file=$venv/ros_setup.bash
# Debian packages of PyKDL (the PyPI `pykdl` is a broken sdist); bookworm's versions.
kdl_debs=(python3-pykdl=1.5.1-2+b4 liborocos-kdl1.5=1.5.1-2+b4)

say() { echo "[dev] ROS tools: $*" >&2; }

skip() {
  rm -f "$setup_file"
  echo "skipped: $1" > "$status"
  echo "[dev] ROS tools skipped (ros2 CLI, launch, crtk_msgs, dVRK client): $1" >&2
  exit 0
}

[ -d "$vendor" ] || skip "no vendored sources at $(realpath -m "$vendor") (set GRIP_FORCE_VENDOR to shared/vendor)"
vendor=$(cd "$vendor" && pwd)
for sub in ros2/ros2cli ros2/rosidl_runtime_py ros2/launch ros2/launch_ros \
           ros2/rcl_interfaces/composition_interfaces crtk_msgs control_msgs crtk_python_client \
           dvrk_python; do
  [ -d "$vendor/$sub" ] || skip "$vendor/$sub is missing"
done
for tool in cmake make g++; do
  command -v "$tool" >/dev/null || { say "needs $tool (Debian: apt-get install cmake g++ make)"; exit 1; }
done

mkdir -p "$ros/stamps" "$ros/logs" "$ros/src"
echo "building" > "$status"

# The build environment: ament finds the wheels' packages in the venv's prefix.
export AMENT_PREFIX_PATH=$venv ROS_VERSION=2 ROS_PYTHON_VERSION=3 ROS_DISTRO=jazzy
export PATH=$venv/bin:$PATH
unset COLCON_PREFIX_PATH CMAKE_PREFIX_PATH

tree_key() {  # content hash of files (or folders of files)
  local p
  for p in "$@"; do
    if [ -d "$p" ]; then
      (cd "$p" && find . -type f ! -name '*.pyc' -print0 | sort -z | xargs -0 sha256sum)
    elif [ -e "$p" ]; then
      sha256sum "$p"
    else
      echo "missing $p"
    fi
  done | sha256sum | cut -d' ' -f1
}

# step NAME KEY FUNCTION: run FUNCTION unless the stamp of NAME holds KEY.
step() {
  local name=$1 key=$2 fn=$3 stamp=$ros/stamps/$1 log=$ros/logs/$1.log
  if [ "$(cat "$stamp" 2>/dev/null)" = "$key" ]; then
    return 0
  fi
  rm -f "$stamp"
  local t0=$SECONDS
  if ! "$fn" > "$log" 2>&1; then
    say "$name failed; the last lines of $log:"
    tail -n 25 "$log" >&2
    echo "failed: $name (see $log)" > "$status"
    exit 1
  fi
  say "$name done ($((SECONDS - t0)) s)"
  echo "$key" > "$stamp"
}

copy_src() {  # a fresh copy of a vendored folder under VENV/ros/src (pip writes into it)
  rm -rf "${ros:?}/src/$2"
  mkdir -p "$(dirname "$ros/src/$2")"
  cp -a "$vendor/$1" "$ros/src/$2"
}

pins_key=$(tree_key "$root/requirements.txt" "$root/constraints.txt")

# 1. The wheels' CMake files name the build container's Python: repoint them (idempotent,
#    cheap; redone every time since a pip install may have brought new files).
"$py" "$root/tools/fix_wheel_cmake_paths.py" "$venv" > "$ros/logs/fix_wheel_cmake_paths.log"

# 2. ros2cli, rosidl_runtime_py, launch*, ros2launch.
python_tools() {
  copy_src ros2 ros2
  local s=$ros/src/ros2
  "$py" -m pip install --no-deps --no-build-isolation \
    "$s"/ros2cli/{ros2cli,ros2pkg,ros2run,ros2node,ros2service,ros2param,ros2topic,ros2interface,ros2lifecycle,ros2action} \
    "$s/rosidl_runtime_py" "$s"/launch/{launch,launch_xml,launch_yaml} "$s"/launch_ros/{launch_ros,ros2launch}
}
# pip builds one package at a time: run it beside the cmake builds below (2 cores).
step ros2cli_launch "$(tree_key "$vendor/ros2/ros2cli" "$vendor/ros2/rosidl_runtime_py" \
  "$vendor/ros2/launch" "$vendor/ros2/launch_ros")-$pins_key" python_tools &
python_tools_pid=$!

# 3. composition_interfaces: plain cmake, installed into the venv's prefix.
composition_interfaces() {
  copy_src ros2/rcl_interfaces rcl_interfaces
  local b=$ros/build/composition_interfaces
  rm -rf "$b" && mkdir -p "$b"
  cmake -S "$ros/src/rcl_interfaces/composition_interfaces" -B "$b" -DCMAKE_INSTALL_PREFIX="$venv" \
    -DCMAKE_PREFIX_PATH="$venv" -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$py"
  cmake --build "$b" -j 2
  cmake --install "$b"
}
step composition_interfaces "$(tree_key "$vendor/ros2/rcl_interfaces/composition_interfaces")-$pins_key" \
  composition_interfaces

colcon_build() {  # colcon build into VENV/ros/install; arguments: colcon build options
  (cd "$ros" && colcon --log-base "$ros/log" build --build-base "$ros/build" \
    --install-base "$ros/install" "$@")
}

# 4. crtk_msgs, unless the environment has it (a ROS machine with it installed).
crtk_msgs_source=built
crtk_msgs() {
  copy_src crtk_msgs ws/crtk_msgs
  # Its CMakeLists finds rclcpp; message generation does not use it and it has no wheel.
  mkdir -p "$ros/build/rclcpp_stub"
  printf '%s\n' '# Generated by tools/ros_tools.sh: crtk_msgs asks for rclcpp, messages do not need it.' \
    'set(rclcpp_FOUND TRUE)' > "$ros/build/rclcpp_stub/rclcppConfig.cmake"
  colcon_build --base-paths "$ros/src/ws/crtk_msgs" --packages-select crtk_msgs \
    --cmake-args -DBUILD_TESTING=OFF -Drclcpp_DIR="$ros/build/rclcpp_stub" -DPython3_EXECUTABLE="$py"
}
if env -u PYTHONPATH "$py" -c 'import crtk_msgs.msg' 2>/dev/null && [ ! -d "$ros/install/crtk_msgs" ]; then
  crtk_msgs_source=environment
  say "crtk_msgs is importable already: not built"
else
  step crtk_msgs "$(tree_key "$vendor/crtk_msgs")-$pins_key" crtk_msgs
fi

# 4b. control_msgs (the grippers' actions), likewise unless the environment has it: with
#     the same ament_cmake + rosidl wheels, installed into the venv's prefix (as
#     composition_interfaces), so that the venv's Python imports it without sourcing
#     anything (the controller's in-process tests, `.venv/bin/python -c 'import control_msgs'`).
control_msgs_source=built
control_msgs() {
  copy_src control_msgs control_msgs
  local b=$ros/build/control_msgs
  rm -rf "$b" && mkdir -p "$b"
  cmake -S "$ros/src/control_msgs/control_msgs" -B "$b" -DCMAKE_INSTALL_PREFIX="$venv" \
    -DCMAKE_PREFIX_PATH="$venv" -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$py"
  cmake --build "$b" -j 2
  cmake --install "$b"
}
control_msgs_key="$(tree_key "$vendor/control_msgs")-$pins_key"
if env -u PYTHONPATH "$py" -c 'import control_msgs.action' 2>/dev/null \
    && [ ! -f "$ros/build/control_msgs/install_manifest.txt" ]; then
  control_msgs_source=environment
  say "control_msgs is importable already: not built"
else
  step control_msgs "$control_msgs_key" control_msgs
fi

wait "$python_tools_pid" || exit 1

# 5. PyKDL from Debian, the CRTK and dVRK Python clients.
pykdl() {
  local debs=$ros/debs
  rm -rf "$debs" "$ros/pykdl" && mkdir -p "$debs"
  if ! (cd "$debs" && apt-get download "${kdl_debs[@]}"); then
    apt-get update -qq  # a fresh machine has no package lists yet
    (cd "$debs" && apt-get download "${kdl_debs[@]}")
  fi
  for deb in "$debs"/*.deb; do dpkg -x "$deb" "$ros/pykdl"; done
  local so
  so=$(find "$ros/pykdl" -name 'PyKDL*.so' | head -n 1)
  [ -n "$so" ] || { echo "no PyKDL module in ${kdl_debs[*]}"; return 1; }
}
step pykdl "${kdl_debs[*]}" pykdl

clients() {
  copy_src crtk_python_client crtk_python_client
  copy_src dvrk_python dvrk_python
  "$py" -m pip install --no-deps --no-build-isolation "$ros/src/crtk_python_client" "$ros/src/dvrk_python"
}
step crtk_dvrk_clients "$(tree_key "$vendor/crtk_python_client" "$vendor/dvrk_python")-$pins_key" clients

# 6. This package, as on a ROS machine (symlinked: the installed files are the sources).
package_key=$(
  cd "$root" && { cat setup.py setup.cfg package.xml; ls -R config launch resource 2>/dev/null || true; } | sha256sum)
grip_force_ros() {
  colcon_build --base-paths "$root" --packages-select grip_force_ros --symlink-install
}
step grip_force_ros "${package_key%% *}" grip_force_ros

# 7. The one file to source.
pykdl_py=$(dirname "$(find "$ros/pykdl" -name 'PyKDL*.so' | head -n 1)")
pykdl_lib=$(dirname "$(find "$ros/pykdl" -name 'liborocos-kdl.so*' | head -n 1)")
cat > "$setup_file" <<EOF
# The ROS 2 environment of $venv (generated by tools/ros_tools.sh; do not edit).
#   source $setup_file
# Then ros2 (run, launch, topic, param, node, lifecycle, ...) works as on a ROS 2 Jazzy
# machine, with rclpy and the messages from the venv's wheels, crtk_msgs, control_msgs, the
# crtk/dvrk Python clients and grip_force_ros (colcon, symlink install: the sources are live).
export ROS_VERSION=2 ROS_PYTHON_VERSION=3 ROS_DISTRO=jazzy
export ROS_AUTOMATIC_DISCOVERY_RANGE=\${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
case ":\${AMENT_PREFIX_PATH:-}:" in *":$venv:"*) ;; *)
  export AMENT_PREFIX_PATH=$venv\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH} ;; esac
case ":\$PATH:" in *":$venv/bin:"*) ;; *) export PATH=$venv/bin:\$PATH ;; esac
case ":\${PYTHONPATH:-}:" in *":$pykdl_py:"*) ;; *)
  export PYTHONPATH=$pykdl_py\${PYTHONPATH:+:\$PYTHONPATH} ;; esac
case ":\${LD_LIBRARY_PATH:-}:" in *":$pykdl_lib:"*) ;; *)
  export LD_LIBRARY_PATH=$pykdl_lib:$venv/lib\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH} ;; esac
# colcon's workspace: grip_force_ros (and crtk_msgs when built here: its typesupport
# libraries go on LD_LIBRARY_PATH, which PYTHONPATH alone would not do).
. "$ros/install/setup.bash"
EOF
echo "ok: crtk_msgs $crtk_msgs_source, control_msgs $control_msgs_source; setup file $setup_file" > "$status"
say "ready: source ${setup_file#"$root"/} (or ./dev ros2 ...)"
