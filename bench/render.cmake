# Synthetic rendering throughput (images/s/core at 640x480, one thread).
add_executable(render ${CMAKE_CURRENT_LIST_DIR}/render.cpp)
target_link_libraries(render PRIVATE poseforest::renderer poseforest::warnings)
