/* Classifies a raw 640x480 depth frame (little-endian uint16 millimetres) with the C API and
   prints the body parts found and each joint's most confident proposal; optionally writes the
   labels (one byte per pixel) to LABELS_OUT.
     classify_c FOREST.pff DEPTH.raw [LABELS_OUT]
   Built by examples/CMakeLists.txt and examples/Makefile; run by the tests (tests/runtime). */
#include <poseforest/poseforest.h>
#include <stdio.h>
#include <stdlib.h>

enum { kWidth = 640, kHeight = 480, kMaxProposals = 1024 };

static int fail(const char* what) {
  fprintf(stderr, "classify_c: %s: %s\n", what, pf_last_error_message());
  return 1;
}

int main(int argc, char** argv) {
  if (argc < 3) {
    fprintf(stderr, "usage: classify_c FOREST.pff DEPTH.raw [LABELS_OUT]\n");
    return 2;
  }
  static uint16_t depth[kWidth * kHeight];
  static uint8_t labels[kWidth * kHeight];
  static pf_joint_proposal proposals[kMaxProposals];
  FILE* in = fopen(argv[2], "rb");
  if (!in || fread(depth, sizeof depth, 1, in) != 1) {
    fprintf(stderr, "classify_c: cannot read %d x %d depth values from %s\n", kWidth, kHeight, argv[2]);
    return 1;
  }
  fclose(in);

  printf("poseforest %s (headers %s)\n", pf_version_string(), POSEFOREST_VERSION_STRING);
  pf_forest* forest = NULL;
  if (pf_forest_load_file(argv[1], &forest) != PF_OK) return fail("load");
  printf("forest: %d trees, depth %d, %zu nodes, %d parts\n", pf_forest_num_trees(forest),
         pf_forest_max_depth(forest), pf_forest_num_nodes(forest), pf_forest_num_parts(forest));

  if (pf_classify(forest, depth, kWidth, kHeight, 0, labels, sizeof labels, NULL, 0) != PF_OK)
    return fail("classify");
  int foreground = 0;
  for (int i = 0; i < kWidth * kHeight; ++i) foreground += labels[i] != 255;
  printf("foreground pixels: %d\n", foreground);

  if (pf_forest_has_joints(forest)) {
    size_t count = 0;
    if (pf_propose_joints(forest, depth, kWidth, kHeight, PF_MEAN_SHIFT, 0, proposals, kMaxProposals, &count,
                          NULL, 0) != PF_OK)
      return fail("joints");
    printf("joint proposals: %zu\n", count);
    for (size_t k = 0; k < count; ++k)
      if (k == 0 || proposals[k].joint != proposals[k - 1].joint) /* the first of a joint is its best */
        printf("  %-11s (%.3f, %.3f, %.3f) m, confidence %.4g\n", pf_joint_name(proposals[k].joint),
               proposals[k].position_m[0], proposals[k].position_m[1], proposals[k].position_m[2],
               proposals[k].confidence);
  }
  pf_forest_free(forest);

  if (argc > 3) {
    FILE* out = fopen(argv[3], "wb");
    if (!out || fwrite(labels, sizeof labels, 1, out) != 1 || fclose(out) != 0) {
      fprintf(stderr, "classify_c: cannot write %s\n", argv[3]);
      return 1;
    }
  }
  return 0;
}
