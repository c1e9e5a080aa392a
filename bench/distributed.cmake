# bench/distributed: the distributed service (coordinator + 1 and 2 worker processes) against
# the single-process engine on one job: bytes and merge time per level, evaluations per CPU-second.
add_executable(distributed ${CMAKE_CURRENT_LIST_DIR}/distributed.cpp)
target_link_libraries(distributed PRIVATE poseforest::coordinator poseforest::worker nlohmann_json::nlohmann_json CLI11::CLI11 poseforest::warnings)
add_dependencies(distributed poseforest)  # the headline runs `poseforest train` (as users do)
