# bench/train: feature evaluations per second per core of the training histogram builder.
add_executable(train train.cpp)
target_link_libraries(train PRIVATE poseforest::engine CLI11::CLI11 poseforest::warnings)
# The scikit-learn side of its side by side (run with /usr/bin/python3).
target_compile_definitions(train PRIVATE POSEFOREST_SKLEARN_SCRIPT="${CMAKE_CURRENT_SOURCE_DIR}/sklearn_side_by_side.py")

# bench/leaf_encoding: the accuracy cost of the forest file's uint8 leaf encoding.
add_executable(leaf_encoding leaf_encoding.cpp)
target_link_libraries(leaf_encoding PRIVATE poseforest::engine CLI11::CLI11 poseforest::warnings)
