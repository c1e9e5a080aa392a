# The renderer proper, part of poseforest::renderer (renderer/CMakeLists.txt): procedural bodies,
# part labels, skinning, pose sampling, headless EGL rendering, scenes + Kinect noise, and the
# SyntheticRenderer used by workers and `poseforest render` (apps/commands/render_command.cpp).
target_sources(poseforest_renderer PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/procedural_body.cpp
  ${CMAKE_CURRENT_LIST_DIR}/part_labels.cpp
  ${CMAKE_CURRENT_LIST_DIR}/skinning.cpp
  ${CMAKE_CURRENT_LIST_DIR}/pose_sampler.cpp
  ${CMAKE_CURRENT_LIST_DIR}/egl_renderer.cpp
  ${CMAKE_CURRENT_LIST_DIR}/scene.cpp
  ${CMAKE_CURRENT_LIST_DIR}/synthetic_source.cpp
  ${CMAKE_CURRENT_LIST_DIR}/montage.cpp
  ${CMAKE_CURRENT_LIST_DIR}/scene_assets.cpp
)
target_link_libraries(poseforest_renderer PRIVATE PkgConfig::EGL PkgConfig::GLES)

# Writes the pictures in docs/renderer/ (not installed; run by hand: render_docs docs/renderer
# [DATA_DIR]: with DATA_DIR, also pictures of the asset bodies).
add_executable(render_docs ${CMAKE_CURRENT_LIST_DIR}/tools/render_docs.cpp)
target_link_libraries(render_docs PRIVATE poseforest::renderer poseforest::warnings)
target_compile_definitions(render_docs PRIVATE POSEFOREST_DOCS_WITH_ASSETS=1)
# docs/renderer/sensor_models.png (run by hand: sensor_docs docs/renderer/sensor_models.png).
add_executable(sensor_docs ${CMAKE_CURRENT_LIST_DIR}/tools/sensor_docs.cpp)
# Its command line on CLI11, as poseforest-poselib's (Debian libcli11-dev, header-only).
find_package(CLI11 CONFIG REQUIRED)
target_link_libraries(sensor_docs PRIVATE poseforest::renderer CLI11::CLI11 poseforest::warnings)
