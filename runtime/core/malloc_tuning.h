#pragma once
// glibc malloc settings for poseforest's processes (training, workers, inference).
//
// By default glibc returns freed memory to the kernel eagerly: blocks of 128 KiB and more are
// their own mmap and go back with munmap, and free space at the top of a heap goes back once it
// exceeds a threshold that starts at 128 KiB. Training allocates and frees buffers of that size
// all the time (histograms per batch of nodes, cut tables, sample lists, frames of subtree
// tasks, protobuf replies), so each round faulted the same pages in again: measured on the
// default job of bench/distributed, 50k page faults for two engine runs and 60k for one
// 2-worker service run, about 8 % of their CPU time. KeepFreedMemory() raises the mmap
// threshold to 32 MiB and the trim threshold to 128 MiB (and so turns off glibc's dynamic
// thresholds): freed blocks stay in the process for the next round.
// Cost: each malloc arena may keep up to 128 MiB of free memory instead of returning it.
// A user who sets any glibc.malloc tunable in GLIBC_TUNABLES keeps their own settings.

namespace poseforest::core {

/// Applies the settings above (once per process; later calls do nothing). Returns false when it
/// left malloc alone (GLIBC_TUNABLES names a glibc.malloc tunable, or not glibc).
bool KeepFreedMemory();

}  // namespace poseforest::core
