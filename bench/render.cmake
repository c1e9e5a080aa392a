# Synthetic rendering throughput (images/s/core at 640x480, one thread).
add_executable(render ${CMAKE_CURRENT_LIST_DIR}/render.cpp)
target_link_libraries(render PRIVATE poseforest::renderer CLI11::CLI11 poseforest::warnings)

# bench/pipeline: classification + joint proposals on rendered frames, with joint AP (mAP).
add_executable(pipeline pipeline.cpp)
target_link_libraries(pipeline PRIVATE poseforest::renderer poseforest::runtime poseforest::apps poseforest::warnings)
