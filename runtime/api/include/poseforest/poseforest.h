/* poseforest.h: the C API of the poseforest runtime (body parts and 3D joint proposals from
   single depth images, Shotton et al. 2011). Reference: docs/runtime/api.md.

   Conventions
   - Every function that can fail returns a pf_status; PF_OK (0) is success. The message of the
     last failure on the calling thread is pf_last_error_message(): the same text the
     `poseforest` program prints after "poseforest infer: " (e.g. "DataLoss: f.pff: ...").
   - Handles are opaque; a pf_forest is created by pf_forest_load_file / pf_forest_load_memory
     and destroyed by pf_forest_free. Output buffers are owned by the caller; the library keeps
     no pointer to them after a call returns. No function throws or aborts on bad input.
   - Depth images: row-major uint16 millimetres, width * height values, 0 = no reading
     (background). Pixel (x, y) is depth_mm[y * width + x].
   - Thread safety: a loaded pf_forest is immutable; any number of threads may call
     pf_classify / pf_propose_joints / the pf_forest_* queries on the same forest at once (each
     call uses its own scratch memory; num_threads = OpenMP threads inside one call, 0 = all
     cores). pf_forest_free must not run concurrently with other calls on that forest.
     pf_last_error_message is per thread.
   - Versioning: see poseforest/version.h (compile time) and pf_version() (run time). Until
     1.0 the ABI may change with each minor version; the shared library's SONAME carries
     major.minor (libposeforest.so.0.4). Symbols are prefixed pf_ / PF_; nothing else is
     exported. */
#ifndef POSEFOREST_POSEFOREST_H_
#define POSEFOREST_POSEFOREST_H_

#include <stddef.h>
#include <stdint.h>

#include "poseforest/version.h"

#if defined(_WIN32)
#if defined(PF_BUILDING_LIBRARY)
#define PF_API __declspec(dllexport)
#elif defined(PF_STATIC)
#define PF_API
#else
#define PF_API __declspec(dllimport)
#endif
#else
#define PF_API __attribute__((visibility("default")))
#endif

#ifdef __cplusplus
extern "C" {
#endif

/** Outcome of a call. The values are stable (they are part of the ABI). */
typedef enum pf_status {
  PF_OK = 0,
  PF_INVALID_ARGUMENT = 1, /**< a bad value from the caller (null pointer, size, method) */
  PF_DATA_LOSS = 2,        /**< a corrupt or truncated forest */
  PF_VERSION_MISMATCH = 3, /**< a forest file of another major format version */
  PF_IO = 4,               /**< the OS failed to open or read a file */
  PF_NOT_FOUND = 5,        /**< no such file */
  PF_UNIMPLEMENTED = 6,
  PF_INTERNAL = 7,         /**< a bug: please report it with the message */
  PF_BUFFER_TOO_SMALL = 8, /**< an output buffer is too small; the needed size was returned */
  PF_OUT_OF_MEMORY = 9
} pf_status;

/** Joint proposal method (section 3.4 of the paper). */
typedef enum pf_proposal_method {
  PF_MEAN_SHIFT = 0,     /**< weighted Gaussian mean shift (the paper's main method) */
  PF_FAST_CLUSTERING = 1 /**< bottom-up clustering of the above-threshold pixels (faster) */
} pf_proposal_method;

/** A loaded, validated forest (opaque). */
typedef struct pf_forest pf_forest;

/** One 3D joint proposal. */
typedef struct pf_joint_proposal {
  int32_t joint;       /**< 0 .. pf_num_joints()-1, see pf_joint_name */
  float position_m[3]; /**< x right, y down, z forward; metres, camera frame (Kinect v1 intrinsics) */
  float pixel[2];      /**< where the surface mode projects: x (column), y (row), pixels */
  float confidence;    /**< summed weight (P * depth^2, m^2) of the seed pixels reaching the mode */
} pf_joint_proposal;

/* ---- version and errors -------------------------------------------------------------------- */

/** Version of the loaded library as POSEFOREST_VERSION_NUMBER encodes it (0x00MMmmpp). */
PF_API uint32_t pf_version(void);
/** Version of the loaded library, "0.4.0". Static storage. */
PF_API const char* pf_version_string(void);
/** Name of a status, "DataLoss" (as messages start), "Ok" for PF_OK, "Unknown" for other values.
    Static storage. */
PF_API const char* pf_status_name(pf_status status);
/** Message of the last call on this thread that returned a pf_status: "" after PF_OK. Valid
    until the next such call on this thread. Never NULL. */
PF_API const char* pf_last_error_message(void);

/* ---- forests ------------------------------------------------------------------------------- */

/** Loads and fully validates a forest file (.pff, runtime/FORMAT.md). On success *out is a new
    forest to release with pf_forest_free; on failure *out is NULL. */
PF_API pf_status pf_forest_load_file(const char* path, pf_forest** out);
/** The same from `size` bytes in memory (copied: the caller may free them afterwards).
    `source` names the bytes in messages (NULL: "memory"). */
PF_API pf_status pf_forest_load_memory(const void* bytes, size_t size, const char* source, pf_forest** out);
/** Releases a forest. NULL is allowed. */
PF_API void pf_forest_free(pf_forest* forest);

/** Number of trees (>= 1), or -1 for NULL. */
PF_API int pf_forest_num_trees(const pf_forest* forest);
/** Number of body parts the forest labels (31 for the paper's taxonomy), or -1 for NULL. */
PF_API int pf_forest_num_parts(const pf_forest* forest);
/** Depth of the deepest tree (edges from the root), or -1 for NULL. */
PF_API int pf_forest_max_depth(const pf_forest* forest);
/** Total nodes over all trees, or 0 for NULL. */
PF_API size_t pf_forest_num_nodes(const pf_forest* forest);
/** Name of part `part` ("LU_head"), NULL if out of range. Valid while the forest lives. */
PF_API const char* pf_forest_part_name(const pf_forest* forest, int part);
/** 1 if the forest has the paper's 31-part taxonomy (needed for joint proposals), else 0. */
PF_API int pf_forest_has_joints(const pf_forest* forest);

/** Number of joints proposals are made for (16). */
PF_API int pf_num_joints(void);
/** Name of joint `joint` ("head", "L_shoulder"), NULL if out of range. Static storage. */
PF_API const char* pf_joint_name(int joint);

/* ---- inference ----------------------------------------------------------------------------- */

/** Labels every pixel of a depth image (eq. 2: leaf distributions averaged over the trees).
    labels (may be NULL): width*height bytes, the most likely part per pixel (ties: the lower
      part), 255 where the depth is 0. `labels_len` is the buffer's size in bytes.
    distributions (may be NULL): width*height*num_parts floats, P(part | pixel) at
      [(y*width + x)*num_parts + part]; all zero where the depth is 0. `distributions_len`
      is the buffer's size in floats.
    At least one of the two must be given; a buffer that is too small gives
    PF_BUFFER_TOO_SMALL and nothing is written. The values equal `poseforest infer --labels
    --distributions` byte for byte. width, height in 1..32768. */
PF_API pf_status pf_classify(const pf_forest* forest, const uint16_t* depth_mm, int width, int height,
                             int num_threads, uint8_t* labels, size_t labels_len, float* distributions,
                             size_t distributions_len);

/** Classifies the image and proposes 3D joints from the parts (section 3.4), with the proposal
    parameters stored in the forest for the method (else the paper's means), as
    `poseforest infer --joints` does. The forest must have the paper's 31 parts
    (pf_forest_has_joints), else PF_INVALID_ARGUMENT.
    Writes every proposal, grouped by joint in joint order, most confident first within a joint,
    into proposals[0 .. *count); *count is set to the number of proposals found. If that exceeds
    `capacity`, nothing is written and PF_BUFFER_TOO_SMALL is returned (call again with a
    buffer of *count; proposals may be NULL when capacity is 0).
    labels (may be NULL): as in pf_classify, from the same classification. */
PF_API pf_status pf_propose_joints(const pf_forest* forest, const uint16_t* depth_mm, int width, int height,
                                   pf_proposal_method method, int num_threads, pf_joint_proposal* proposals,
                                   size_t capacity, size_t* count, uint8_t* labels, size_t labels_len);

/* ---- skeletons (as `poseforest live`) ------------------------------------------------------ */

/** A stream of depth frames turned into per-person skeletons (opaque): people segmentation, the
    forest's parts, mean-shift joint proposals and skeletons with ids that stay with people over
    the stream, as `poseforest live` (docs/runtime/live.md). */
typedef struct pf_skeleton_stream pf_skeleton_stream;

/** A joint's state, pf_skeleton_joint.state (the JSON Lines record and the ROS 2 message name the
    same three). The values are stable (they are part of the ABI).
    PF_JOINT_NOT_TRACKED: not found, or found but failing a tracking rule.
    PF_JOINT_INFERRED: found, not tracked, but placed by a confident offset vote behind the
      person's visible surface: a hidden joint the body model puts there (Azure Kinect Body
      Tracking's "LOW: predicted"). Forests without offset votes never give it.
    PF_JOINT_TRACKED: tracked == 1. */
#define PF_JOINT_NOT_TRACKED 0
#define PF_JOINT_INFERRED 1
#define PF_JOINT_TRACKED 2

/** One joint of a skeleton. */
typedef struct pf_skeleton_joint {
  int32_t found;       /**< 1 if a proposal lies on the person (position_m and pixel are valid), else 0 */
  int32_t tracked;     /**< 1 if the joint passes every tracking rule of docs/runtime/live.md, else 0 */
  float position_m[3]; /**< x right, y down, z forward; metres, camera frame; zeros when not found */
  float pixel[2];      /**< where position_m projects: x (column), y (row), pixels; zeros when not found */
  float confidence;    /**< 0..1: the forest's calibrated precision (or the fallback); 0 when not found */
  int32_t state;       /**< PF_JOINT_TRACKED exactly when tracked == 1; PF_JOINT_INFERRED only when
                            found == 1 and tracked == 0; else PF_JOINT_NOT_TRACKED (since 0.4) */
} pf_skeleton_joint;

/** Name of a joint state: "not_tracked", "inferred", "tracked" (the JSON Lines record's words),
    NULL for any other value. Static storage. */
PF_API const char* pf_joint_state_name(int32_t state);

/** Number of joints in a pf_skeleton (the paper's 16, pf_joint_name order). */
#define PF_SKELETON_JOINTS 16

/** One person's skeleton. */
typedef struct pf_skeleton {
  int32_t id;          /**< >= 1, stable over the stream (nearest centroid between frames) */
  int32_t pixels;      /**< pixels of the person's mask */
  float centroid_m[3]; /**< mean of the mask's 3D points, metres, camera frame */
  pf_skeleton_joint joints[PF_SKELETON_JOINTS]; /**< in pf_joint_name order */
} pf_skeleton;

/** Starts a stream over `forest` (which must outlive it and have the paper's 31 parts, else
    PF_INVALID_ARGUMENT). Frames are raw (segmented into people: floor, depth bands, components)
    or pre-segmented (only people have depth: everything with depth is one person), told apart
    per frame as `poseforest live` does; proposals use mean shift with the forest's parameters;
    confidences use the forest's calibration table if it has one for mean shift. num_threads:
    OpenMP threads per frame, 0 = all cores. On success *out is a new stream to release with
    pf_skeleton_stream_free. */
PF_API pf_status pf_skeleton_stream_create(const pf_forest* forest, int num_threads,
                                           pf_skeleton_stream** out);
/** Releases a stream. NULL is allowed. */
PF_API void pf_skeleton_stream_free(pf_skeleton_stream* stream);

/** Runs one frame (Kinect v1 intrinsics; timestamps in seconds, not decreasing) and writes its
    skeletons, ordered by id, into skeletons[0 .. *count). The stream keeps the frame's result:
    if *count exceeds `capacity`, nothing is written, PF_BUFFER_TOO_SMALL is returned and
    pf_skeleton_stream_last gives the same skeletons without running the frame again
    (skeletons may be NULL when capacity is 0). A stream is not thread-safe: one thread at a
    time per stream (streams on one forest may run in parallel). */
PF_API pf_status pf_skeleton_stream_process(pf_skeleton_stream* stream, const uint16_t* depth_mm, int width,
                                            int height, double timestamp_s, pf_skeleton* skeletons,
                                            size_t capacity, size_t* count);
/** The skeletons of the last frame processed (none before the first), with the buffer protocol
    of pf_skeleton_stream_process. */
PF_API pf_status pf_skeleton_stream_last(const pf_skeleton_stream* stream, pf_skeleton* skeletons,
                                         size_t capacity, size_t* count);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* POSEFOREST_POSEFOREST_H_ */
