# bench/train: feature evaluations per second per core of the training histogram builder.
add_executable(train train.cpp)
target_link_libraries(train PRIVATE poseforest::coordinator poseforest::warnings)
