# Cross-compiling poseforest's runtime for 64-bit ARM Linux (Raspberry Pi 4/5, Jetson, Rockchip
# boards) with Debian's cross toolchain (g++-aarch64-linux-gnu; scripts/cross-arm64.sh installs
# it). OpenMP is the cross gcc's libgomp; Eigen and Catch2 v2 are header-only, so the host's
# packages (/usr/share/eigen3, /usr/lib/cmake/Catch2) serve. Tests run under qemu-user
# (CMAKE_CROSSCOMPILING_EMULATOR), so `ctest` in the build folder works on an x86-64 host.
#   cmake -S . -B build-arm64 --toolchain cmake/toolchains/aarch64-linux-gnu.cmake \
#     -DPOSEFOREST_TRAINING=OFF -DPOSEFOREST_BENCH=OFF -DPOSEFOREST_DEVICES=OFF -DPOSEFOREST_PYTHON=OFF
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)

set(POSEFOREST_CROSS_TRIPLE aarch64-linux-gnu)
set(CMAKE_C_COMPILER ${POSEFOREST_CROSS_TRIPLE}-gcc)
set(CMAKE_CXX_COMPILER ${POSEFOREST_CROSS_TRIPLE}-g++)
# Debian's multiarch-less cross sysroot (libc6-dev-arm64-cross).
set(POSEFOREST_CROSS_SYSROOT /usr/${POSEFOREST_CROSS_TRIPLE})

# Libraries only from the target's folders; headers and CMake packages also from the host's
# (Eigen, Catch2: header-only, architecture-independent); programs (python3, bash) from the host.
set(CMAKE_FIND_ROOT_PATH ${POSEFOREST_CROSS_SYSROOT} /usr/lib/${POSEFOREST_CROSS_TRIPLE})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE BOTH)
# libspng and zlib (the runtime links them): Debian's arm64 packages unpacked into
# POSEFOREST_CROSS_DEPS by scripts/cross-arm64.sh (default: deps/ in the build folder).
if(NOT POSEFOREST_CROSS_DEPS)
  set(POSEFOREST_CROSS_DEPS ${CMAKE_BINARY_DIR}/deps)
endif()
# The compiler checks' try_compile projects read this file too: same folder there, or they would
# point pkg-config (an environment variable of this one process) at their own.
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES POSEFOREST_CROSS_DEPS)
list(APPEND CMAKE_FIND_ROOT_PATH ${POSEFOREST_CROSS_DEPS})
# Programs that link the static libposeforest name them -lspng -lz (its exported target).
set(CMAKE_EXE_LINKER_FLAGS_INIT "-L${POSEFOREST_CROSS_DEPS}/usr/lib/${POSEFOREST_CROSS_TRIPLE} \
-Wl,-rpath-link,${POSEFOREST_CROSS_DEPS}/lib/${POSEFOREST_CROSS_TRIPLE}")
set(CMAKE_SHARED_LINKER_FLAGS_INIT ${CMAKE_EXE_LINKER_FLAGS_INIT})
# pkg-config sees the target's .pc files only: the host's x86-64 libraries (cpp-httplib's .so,
# libfreenect, OpenNI2) are not found, so what needs them is left out as on a machine without them.
set(ENV{PKG_CONFIG_LIBDIR} /usr/lib/${POSEFOREST_CROSS_TRIPLE}/pkgconfig:${POSEFOREST_CROSS_SYSROOT}/lib/pkgconfig:${POSEFOREST_CROSS_DEPS}/usr/lib/${POSEFOREST_CROSS_TRIPLE}/pkgconfig)
set(ENV{PKG_CONFIG_PATH} "")

# -march=native means the build machine's CPU: a cross build targets the generic ARMv8-A
# (every 64-bit Pi, Jetson and Rockchip board runs it; NEON is part of it).
set(POSEFOREST_NATIVE OFF CACHE BOOL "Optimize for this machine's CPU (-march=native)" FORCE)

# ctest (and add_test commands naming a target) run the aarch64 programs through qemu-user.
find_program(POSEFOREST_QEMU_AARCH64 qemu-aarch64)
if(POSEFOREST_QEMU_AARCH64)
  set(CMAKE_CROSSCOMPILING_EMULATOR ${POSEFOREST_QEMU_AARCH64} -L ${POSEFOREST_CROSS_SYSROOT} -E
      LD_LIBRARY_PATH=${POSEFOREST_CROSS_DEPS}/usr/lib/${POSEFOREST_CROSS_TRIPLE}:${POSEFOREST_CROSS_DEPS}/lib/${POSEFOREST_CROSS_TRIPLE})
endif()
