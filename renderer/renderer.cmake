# The renderer proper: procedural bodies, part labels, skinning, pose sampling, headless EGL
# rendering, scenes + Kinect noise, and the SyntheticRenderer used by workers and `poseforest render`.
add_library(poseforest_renderer STATIC
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
add_library(poseforest::renderer ALIAS poseforest_renderer)
target_link_libraries(poseforest_renderer
  PUBLIC poseforest::skeleton poseforest::assets poseforest::runtime Eigen3::Eigen
  PRIVATE PkgConfig::EGL PkgConfig::GLES poseforest::warnings)

# `poseforest render`: writes a synthetic data set and a preview montage.
if(EXISTS ${CMAKE_CURRENT_LIST_DIR}/cli/render_command.cpp)
  add_library(poseforest_render_cli STATIC ${CMAKE_CURRENT_LIST_DIR}/cli/render_command.cpp)
  add_library(poseforest::render_cli ALIAS poseforest_render_cli)
  target_link_libraries(poseforest_render_cli PUBLIC poseforest::renderer poseforest::cli_runtime Threads::Threads PRIVATE nlohmann_json::nlohmann_json poseforest::warnings)
  # Default --data folder (POSEFOREST_DATA_DIR in the environment wins).
  target_compile_definitions(poseforest_render_cli PRIVATE POSEFOREST_RENDER_DATA_DIR="${POSEFOREST_DATA_DIR}")
  set_property(GLOBAL APPEND PROPERTY POSEFOREST_CLI_LIBS poseforest_render_cli)
  set_property(GLOBAL APPEND PROPERTY POSEFOREST_CLI_DEFS POSEFOREST_HAS_RENDER=1)
endif()

# Writes the pictures in docs/renderer/ (not installed; run by hand: render_docs docs/renderer).
add_executable(render_docs ${CMAKE_CURRENT_LIST_DIR}/tools/render_docs.cpp)
target_link_libraries(render_docs PRIVATE poseforest::renderer poseforest::warnings)
if(TARGET poseforest_assets)  # also pictures of the asset bodies (render_docs OUT DATA_DIR)
  target_link_libraries(render_docs PRIVATE poseforest::assets)
  target_compile_definitions(render_docs PRIVATE POSEFOREST_DOCS_WITH_ASSETS=1)
endif()
# docs/renderer/sensor_models.png (run by hand: sensor_docs docs/renderer/sensor_models.png).
add_executable(sensor_docs ${CMAKE_CURRENT_LIST_DIR}/tools/sensor_docs.cpp)
target_link_libraries(sensor_docs PRIVATE poseforest::renderer poseforest::warnings)
