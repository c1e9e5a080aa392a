#include "renderer/egl_renderer.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl3.h>

#include <algorithm>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <string_view>
#include <unordered_map>

#include "runtime/core/body_parts.h"

namespace poseforest::renderer {

/// Winding of outward (camera-facing) triangles in window space for a transform with positive
/// determinant: the projection renders rows top-down (a y flip), so counter-clockwise meshes
/// arrive clockwise. Checked by test_egl_renderer's exact-depth box test.
constexpr bool kFrontIsCcw = false;
namespace {

using core::ErrorCode;
using core::Status;

constexpr const char* kVertexShader = R"(#version 300 es
layout(location = 0) in vec3 a_pos;
layout(location = 1) in uvec4 a_joint;
layout(location = 2) in vec4 a_weight;
layout(location = 3) in uint a_part;
uniform vec4 u_joint[72];  // 24 joints x 3 rows of camera_from_rest
uniform mat4 u_proj;
uniform uint u_part_map[32];
flat out uint v_part;
out float v_z;
void main() {
  vec4 p = vec4(a_pos, 1.0);
  int j = int(a_joint[0]) * 3;
  vec3 q = vec3(dot(u_joint[j], p), dot(u_joint[j + 1], p), dot(u_joint[j + 2], p));
  if (a_weight[0] != 1.0) {  // most vertices follow one bone: skip the blend (and its gathers)
    q *= a_weight[0];
    for (int i = 1; i < 4; ++i) {
      j = int(a_joint[i]) * 3;
      q += a_weight[i] * vec3(dot(u_joint[j], p), dot(u_joint[j + 1], p), dot(u_joint[j + 2], p));
    }
  }
  v_z = q.z;
  v_part = u_part_map[a_part];
  gl_Position = u_proj * vec4(q, 1.0);
}
)";

// Depth (mm, 16 bits) in R and G, the label in B, the person id in A: exact through an RGBA8 attachment
// because k / 255 converts back to k, and one glReadPixels of 4 bytes per pixel returns everything.
constexpr const char* kFragmentShader = R"(#version 300 es
precision highp float;
precision highp int;
flat in uint v_part;
in float v_z;
uniform float u_person;  // 1-based person id of the draw (A channel), 0 = cleared
layout(location = 0) out vec4 o_colour;
void main() {
  uint d = uint(clamp(floor(v_z * 1000.0 + 0.5), 0.0, 65535.0));
  o_colour = vec4(float(d & 255u), float(d >> 8u), float(v_part), u_person) / 255.0;
}
)";

struct GpuVertex {
  float pos[3];
  uint8_t joint[4];
  float weight[4];
  uint8_t part;
  uint8_t pad[3];
};
static_assert(sizeof(GpuVertex) == 36);

bool HasExtension(const char* list, std::string_view ext) {
  if (!list) return false;
  std::string_view s(list);
  size_t pos = 0;
  while ((pos = s.find(ext, pos)) != std::string_view::npos) {
    const bool start_ok = pos == 0 || s[pos - 1] == ' ';
    const bool end_ok = pos + ext.size() == s.size() || s[pos + ext.size()] == ' ';
    if (start_ok && end_ok) return true;
    pos += ext.size();
  }
  return false;
}

std::string EglErrorString(EGLint e) {
  switch (e) {
    case EGL_SUCCESS:
      return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED:
      return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS:
      return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC:
      return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE:
      return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG:
      return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT:
      return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY:
      return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH:
      return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER:
      return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE:
      return "EGL_BAD_SURFACE";
    default:
      return "EGL error 0x" + [&] {
        char b[16];
        std::snprintf(b, sizeof b, "%x", unsigned(e));
        return std::string(b);
      }();
  }
}

Status CompileShader(GLenum type, const char* src, GLuint* out) {
  GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048] = {};
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    glDeleteShader(s);
    return Status(ErrorCode::kInternal, std::string("EGL renderer: shader compile failed: ") + log);
  }
  *out = s;
  return Status::Ok();
}

}  // namespace

struct EglRenderer::Impl {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  EGLSurface surface = EGL_NO_SURFACE;  // a 1x1 pbuffer when surfaceless contexts are missing
  std::string platform;
  GLuint program = 0, fbo = 0, colour_rb = 0, depth_rb = 0;
  GLint u_joint = -1, u_proj = -1, u_part_map = -1, u_person = -1;
  struct Mesh {
    GLuint vao = 0, vbo = 0, ibo = 0;
    GLsizei index_count = 0;
    bool closed = false;  ///< every edge shared by exactly two triangles, consistently wound
  };
  std::vector<Mesh> meshes;
  std::array<GLuint, 32> identity_map{}, mirror_map{};
  bool mirrored_bound = false, map_set = false;
};

Eigen::Matrix4f ProjectionMatrix(const core::CameraIntrinsics& c, double n, double f) {
  // Window x of pixel column u's centre is u + 0.5, and NDC x = 2 * window_x / W - 1; likewise
  // rows, with image row v at window y = v + 0.5 (so GL row 0 is the top image row).
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
  p(0, 0) = 2.0 * c.fx / c.width;
  p(0, 2) = 2.0 * (c.cx + 0.5) / c.width - 1.0;
  p(1, 1) = 2.0 * c.fy / c.height;
  p(1, 2) = 2.0 * (c.cy + 0.5) / c.height - 1.0;
  p(2, 2) = (f + n) / (f - n);
  p(2, 3) = -2.0 * f * n / (f - n);
  p(3, 2) = 1.0;
  return p.cast<float>();
}

EglRenderer::EglRenderer(std::unique_ptr<Impl> impl, const core::CameraIntrinsics& camera)
    : impl_(std::move(impl)), camera_(camera) {}

EglRenderer::~EglRenderer() {
  if (!impl_ || impl_->display == EGL_NO_DISPLAY) return;
  if (impl_->context != EGL_NO_CONTEXT &&
      eglMakeCurrent(impl_->display, impl_->surface, impl_->surface, impl_->context)) {
    for (auto& m : impl_->meshes) {
      glDeleteVertexArrays(1, &m.vao);
      glDeleteBuffers(1, &m.vbo);
      glDeleteBuffers(1, &m.ibo);
    }
    glDeleteFramebuffers(1, &impl_->fbo);
    glDeleteRenderbuffers(1, &impl_->colour_rb);
    glDeleteRenderbuffers(1, &impl_->depth_rb);
    glDeleteProgram(impl_->program);
    eglMakeCurrent(impl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  }
  if (impl_->surface != EGL_NO_SURFACE) eglDestroySurface(impl_->display, impl_->surface);
  if (impl_->context != EGL_NO_CONTEXT) eglDestroyContext(impl_->display, impl_->context);
  // No eglTerminate: the display is shared by every renderer of the process (EGL returns the
  // same EGLDisplay to each), and terminating it would pull the rug from the others.
}

namespace {

// Candidate displays, most headless-friendly first; what is missing is noted in `tried`.
std::vector<std::pair<std::string, EGLDisplay>> CandidateDisplays(std::string& tried) {
  const char* client_ext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  auto get_platform_display =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  std::vector<std::pair<std::string, EGLDisplay>> candidates;
  if (get_platform_display && HasExtension(client_ext, "EGL_MESA_platform_surfaceless")) {
    candidates.emplace_back(
        "surfaceless", get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr));
  } else {
    tried += " [no EGL_MESA_platform_surfaceless]";
  }
  if (get_platform_display && HasExtension(client_ext, "EGL_EXT_platform_device")) {
    auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    if (query_devices) {
      EGLDeviceEXT devices[16];
      EGLint n = 0;
      if (query_devices(16, devices, &n)) {
        for (EGLint i = 0; i < n; ++i) {
          candidates.emplace_back("device" + std::to_string(i),
                                  get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr));
        }
      }
    }
  }
  candidates.emplace_back("default", eglGetDisplay(EGL_DEFAULT_DISPLAY));
  return candidates;
}

// A display's OpenGL ES 3 context, current on this thread (and its 1x1 pbuffer when surfaceless
// contexts are missing).
struct EglContext {
  EGLContext context = EGL_NO_CONTEXT;
  EGLSurface surface = EGL_NO_SURFACE;
};

// The context of `display`, or none with the reason appended to `tried`.
EglContext OpenContext(EGLDisplay display, std::string& tried) {
  // EGL_SURFACE_TYPE defaults to EGL_WINDOW_BIT, which surfaceless configs lack.
  const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE, EGL_DONT_CARE,
                                   EGL_NONE};
  const EGLint pbuffer_config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE,
                                           EGL_PBUFFER_BIT, EGL_NONE};
  const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 0, EGL_NONE};
  if (display == EGL_NO_DISPLAY) {
    tried += "no-display";
    return {};
  }
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) {
    tried += "eglInitialize=" + EglErrorString(eglGetError());
    return {};
  }
  if (!eglBindAPI(EGL_OPENGL_ES_API)) {
    tried += "eglBindAPI=" + EglErrorString(eglGetError());
    return {};
  }
  const bool surfaceless =
      HasExtension(eglQueryString(display, EGL_EXTENSIONS), "EGL_KHR_surfaceless_context");
  EGLConfig config = nullptr;
  EGLint n = 0;
  if (!eglChooseConfig(display, surfaceless ? config_attribs : pbuffer_config_attribs, &config, 1, &n) ||
      n < 1) {
    tried += "no GLES3 config";
    return {};
  }
  EGLContext ctx = eglCreateContext(display, config, EGL_NO_CONTEXT, context_attribs);
  if (ctx == EGL_NO_CONTEXT) {
    tried += "eglCreateContext=" + EglErrorString(eglGetError());
    return {};
  }
  EGLSurface surface = EGL_NO_SURFACE;
  if (!surfaceless) {
    const EGLint pb[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
    surface = eglCreatePbufferSurface(display, config, pb);
    if (surface == EGL_NO_SURFACE) {
      tried += "eglCreatePbufferSurface=" + EglErrorString(eglGetError());
      eglDestroyContext(display, ctx);
      return {};
    }
  }
  if (!eglMakeCurrent(display, surface, surface, ctx)) {
    tried += "eglMakeCurrent=" + EglErrorString(eglGetError());
    if (surface != EGL_NO_SURFACE) eglDestroySurface(display, surface);
    eglDestroyContext(display, ctx);
    return {};
  }
  return {ctx, surface};
}

// The shader program, compiled and linked into `*program` (set before linking, so the caller
// deletes it whatever the outcome).
Status LinkProgram(GLuint* program) {
  GLuint vs = 0, fs = 0;
  POSEFOREST_RETURN_IF_ERROR(CompileShader(GL_VERTEX_SHADER, kVertexShader, &vs));
  POSEFOREST_RETURN_IF_ERROR(CompileShader(GL_FRAGMENT_SHADER, kFragmentShader, &fs));
  *program = glCreateProgram();
  glAttachShader(*program, vs);
  glAttachShader(*program, fs);
  glLinkProgram(*program);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint linked = 0;
  glGetProgramiv(*program, GL_LINK_STATUS, &linked);
  if (!linked) {
    char log[2048] = {};
    glGetProgramInfoLog(*program, sizeof log, nullptr, log);
    return Status(ErrorCode::kInternal, std::string("EGL renderer: program link failed: ") + log);
  }
  return Status::Ok();
}

}  // namespace

core::Result<std::unique_ptr<EglRenderer>> EglRenderer::Create(const core::CameraIntrinsics& camera,
                                                               double near_m, double far_m) {
  if (camera.width <= 0 || camera.height <= 0 || camera.width > 8192 || camera.height > 8192) {
    return Status(
        ErrorCode::kInvalidArgument,
        "EGL renderer: bad image size " + std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
  if (!(near_m > 0 && far_m > near_m)) {
    return Status(ErrorCode::kInvalidArgument, "EGL renderer: need 0 < near < far");
  }
  auto impl = std::make_unique<Impl>();
  std::string tried;

  // 1. Candidate displays, most headless-friendly first.
  for (auto& [name, display] : CandidateDisplays(tried)) {
    tried += " " + name + ":";
    const EglContext c = OpenContext(display, tried);
    if (c.context == EGL_NO_CONTEXT) continue;
    impl->display = display;
    impl->context = c.context;
    impl->surface = c.surface;
    impl->platform = name;
    break;
  }
  if (impl->context == EGL_NO_CONTEXT) {
    return Status(ErrorCode::kUnimplemented,
                  "EGL renderer: no display could give an OpenGL ES 3 context (tried:" + tried +
                      "). Install Mesa's EGL (libegl-mesa0, libgl1-mesa-dri) or an NVIDIA driver with EGL.");
  }

  std::unique_ptr<EglRenderer> r(new EglRenderer(std::move(impl), camera));
  Impl& im = *r->impl_;
  r->gl_renderer_ = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  r->gl_version_ =
      std::string(reinterpret_cast<const char*>(glGetString(GL_VERSION))) + " [" + im.platform + "]";

  POSEFOREST_RETURN_IF_ERROR(LinkProgram(&im.program));
  im.u_joint = glGetUniformLocation(im.program, "u_joint");
  im.u_proj = glGetUniformLocation(im.program, "u_proj");
  im.u_part_map = glGetUniformLocation(im.program, "u_part_map");
  im.u_person = glGetUniformLocation(im.program, "u_person");
  glUseProgram(im.program);
  const Eigen::Matrix4f proj = ProjectionMatrix(camera, near_m, far_m);
  glUniformMatrix4fv(im.u_proj, 1, GL_FALSE, proj.data());  // Eigen is column-major, like GL
  for (int p = 0; p < 32; ++p) {
    im.identity_map[size_t(p)] = GLuint(p);
    im.mirror_map[size_t(p)] = p < core::kNumParts ? GLuint(core::MirrorPart(p)) : GLuint(p);
  }
  glUniform1uiv(im.u_part_map, 32, im.identity_map.data());
  im.map_set = true;

  glGenRenderbuffers(1, &im.colour_rb);
  glBindRenderbuffer(GL_RENDERBUFFER, im.colour_rb);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, camera.width, camera.height);
  glGenRenderbuffers(1, &im.depth_rb);
  glBindRenderbuffer(GL_RENDERBUFFER, im.depth_rb);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, camera.width, camera.height);
  glGenFramebuffers(1, &im.fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, im.fbo);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, im.colour_rb);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, im.depth_rb);
  const GLenum fb_status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  if (fb_status != GL_FRAMEBUFFER_COMPLETE) {
    return Status(ErrorCode::kInternal, "EGL renderer: framebuffer incomplete (0x" +
                                            std::to_string(fb_status) + ") on " + r->gl_renderer_);
  }
  glViewport(0, 0, camera.width, camera.height);
  glDisable(GL_CULL_FACE);  // enabled per draw for closed meshes (Draw)
  glDisable(GL_BLEND);
  glDisable(GL_DITHER);  // dithering would perturb the encoded bytes
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glClearColor(0.0f, 0.0f, 1.0f, 0.0f);  // depth 0, label 255, person 0
  glClearDepthf(1.0f);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  if (glGetError() != GL_NO_ERROR) {
    return Status(ErrorCode::kInternal, "EGL renderer: GL error during setup on " + r->gl_renderer_);
  }
  r->readback_.resize(size_t(camera.width) * size_t(camera.height) * 4);
  r->ReleaseCurrent();  // the creating thread need not be the rendering thread
  return r;
}

Status EglRenderer::MakeCurrent() {
  if (eglGetCurrentContext() == impl_->context) return Status::Ok();
  if (!eglMakeCurrent(impl_->display, impl_->surface, impl_->surface, impl_->context)) {
    const EGLint e = eglGetError();
    return Status(
        ErrorCode::kInternal,
        "EGL renderer: eglMakeCurrent failed: " + EglErrorString(e) +
            (e == EGL_BAD_ACCESS ? " (the context is still current on another thread: call "
                                   "ReleaseContext() there before moving a renderer between threads)"
                                 : ""));
  }
  return Status::Ok();
}

void EglRenderer::ReleaseCurrent() {
  if (eglGetCurrentContext() == impl_->context) {
    eglMakeCurrent(impl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  }
}

core::Result<int> EglRenderer::UploadMesh(const BodyMesh& mesh) {
  const size_t nv = mesh.vertices.size();
  if (nv == 0 || mesh.triangles.empty()) {
    return Status(ErrorCode::kInvalidArgument, "EGL renderer: mesh '" + mesh.name + "' is empty");
  }
  if (mesh.skin.size() != nv || mesh.part.size() != nv) {
    return Status(ErrorCode::kInvalidArgument,
                  "EGL renderer: mesh '" + mesh.name + "' needs one skin influence and one part per vertex");
  }
  std::vector<GpuVertex> verts(nv);
  for (size_t v = 0; v < nv; ++v) {
    GpuVertex& g = verts[v];
    for (int k = 0; k < 3; ++k) g.pos[k] = mesh.vertices[v][k];
    for (int i = 0; i < 4; ++i) {
      if (mesh.skin[v].joint[size_t(i)] >= kNumSkelJoints) {
        return Status(ErrorCode::kInvalidArgument, "EGL renderer: mesh '" + mesh.name + "' vertex " +
                                                       std::to_string(v) + " has a skin joint out of range");
      }
      g.joint[i] = mesh.skin[v].joint[size_t(i)];
      g.weight[i] = mesh.skin[v].weight[size_t(i)];
    }
    if (mesh.part[v] >= core::kNumParts) {
      return Status(ErrorCode::kInvalidArgument, "EGL renderer: mesh '" + mesh.name + "' vertex " +
                                                     std::to_string(v) + " has part " +
                                                     std::to_string(mesh.part[v]));
    }
    g.part = mesh.part[v];
    g.pad[0] = g.pad[1] = g.pad[2] = 0;
  }
  // Flat labels come from the provoking (last) vertex: rotate each triangle (keeping its
  // winding) so that vertex carries the triangle's majority part.
  std::vector<uint32_t> indices;
  indices.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) {
    for (uint32_t i : t) {
      if (i >= nv) {
        return Status(ErrorCode::kInvalidArgument,
                      "EGL renderer: mesh '" + mesh.name + "' has a triangle index out of range");
      }
    }
    const uint8_t a = mesh.part[t[0]], b = mesh.part[t[1]], c = mesh.part[t[2]];
    int last = 2;          // majority: c unless a == b (then a or b)
    if (a == b) last = 1;  // rotate so t[1] ends last
    if (a == c || b == c) last = 2;
    if (last == 2) {
      indices.insert(indices.end(), {t[0], t[1], t[2]});
    } else {
      indices.insert(indices.end(), {t[2], t[0], t[1]});
    }
  }
  POSEFOREST_RETURN_IF_ERROR(MakeCurrent());
  Impl::Mesh m;
  glGenVertexArrays(1, &m.vao);
  glBindVertexArray(m.vao);
  glGenBuffers(1, &m.vbo);
  glBindBuffer(GL_ARRAY_BUFFER, m.vbo);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(verts.size() * sizeof(GpuVertex)), verts.data(), GL_STATIC_DRAW);
  glGenBuffers(1, &m.ibo);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, m.ibo);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(indices.size() * sizeof(uint32_t)), indices.data(),
               GL_STATIC_DRAW);
  const GLsizei stride = sizeof(GpuVertex);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(GpuVertex, pos)));
  glEnableVertexAttribArray(1);
  glVertexAttribIPointer(1, 4, GL_UNSIGNED_BYTE, stride, reinterpret_cast<void*>(offsetof(GpuVertex, joint)));
  glEnableVertexAttribArray(2);
  glVertexAttribPointer(2, 4, GL_FLOAT, GL_FALSE, stride,
                        reinterpret_cast<void*>(offsetof(GpuVertex, weight)));
  glEnableVertexAttribArray(3);
  glVertexAttribIPointer(3, 1, GL_UNSIGNED_BYTE, stride, reinterpret_cast<void*>(offsetof(GpuVertex, part)));
  glBindVertexArray(0);
  m.index_count = GLsizei(indices.size());
  {
    // Closed and consistently wound: each directed edge appears once and its reverse once.
    std::unordered_map<uint64_t, int> edges;
    edges.reserve(mesh.triangles.size() * 3);
    for (const auto& t : mesh.triangles)
      for (int e = 0; e < 3; ++e) ++edges[uint64_t(t[size_t(e)]) << 32 | t[size_t((e + 1) % 3)]];
    m.closed = !mesh.triangles.empty();
    for (const auto& [key, n] : edges) {
      const uint64_t reverse = (key << 32) | (key >> 32);
      const auto it = edges.find(reverse);
      if (n != 1 || it == edges.end() || it->second != 1) {
        m.closed = false;
        break;
      }
    }
  }
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
    return Status(ErrorCode::kInternal,
                  "EGL renderer: GL error " + std::to_string(e) + " uploading '" + mesh.name + "'");
  }
  impl_->meshes.push_back(m);
  return int(impl_->meshes.size() - 1);
}

Status EglRenderer::BeginFrame() {
  POSEFOREST_RETURN_IF_ERROR(MakeCurrent());
  glBindFramebuffer(GL_FRAMEBUFFER, impl_->fbo);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  return Status::Ok();
}

void EglRenderer::Draw(int handle, const JointMatrices& m, bool mirror_labels, int person) {
  POSEFOREST_CHECK(handle >= 0 && size_t(handle) < impl_->meshes.size());
  POSEFOREST_CHECK(person >= 0 && person <= 255);
  glUniform1f(impl_->u_person, float(person));
  std::array<float, 72 * 4> rows;
  for (int j = 0; j < kNumSkelJoints; ++j) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) rows[size_t((j * 3 + r) * 4 + c)] = m[size_t(j)](r, c);
    }
  }
  glUniform4fv(impl_->u_joint, 72, rows.data());
  if (mirror_labels != impl_->mirrored_bound) {
    glUniform1uiv(impl_->u_part_map, 32,
                  mirror_labels ? impl_->mirror_map.data() : impl_->identity_map.data());
    impl_->mirrored_bound = mirror_labels;
  }
  const Impl::Mesh& mesh = impl_->meshes[size_t(handle)];
  // Closed bodies: only faces towards the camera can be the nearest surface, so cull the rest
  // (about half the triangles). A mirrored transform (negative determinant) flips the winding.
  if (mesh.closed) {
    const double det = m[0].template block<3, 3>(0, 0).determinant();
    glEnable(GL_CULL_FACE);
    glFrontFace((det > 0) == kFrontIsCcw ? GL_CCW : GL_CW);
  } else {
    glDisable(GL_CULL_FACE);
  }
  glBindVertexArray(mesh.vao);
  glDrawElements(GL_TRIANGLES, mesh.index_count, GL_UNSIGNED_INT, nullptr);
}

void EglRenderer::Finish() { glFinish(); }

Status EglRenderer::ReadFrame(core::DepthImage* depth, core::LabelImage* labels, core::LabelImage* people) {
  const int w = camera_.width, h = camera_.height;
  glReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, readback_.data());
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
    return Status(ErrorCode::kInternal,
                  "EGL renderer: GL error 0x" + std::to_string(e) + " while rendering on " + gl_renderer_);
  }
  if (depth->width != w || depth->height != h) *depth = core::DepthImage(w, h);
  if (labels->width != w || labels->height != h) *labels = core::LabelImage(w, h);
  const uint8_t* src = readback_.data();
  uint16_t* d = depth->data();
  uint8_t* l = labels->data();
  const size_t n = size_t(w) * size_t(h);
  for (size_t i = 0; i < n; ++i) {
    d[i] = uint16_t(src[4 * i] | (src[4 * i + 1] << 8));
    l[i] = src[4 * i + 2];
  }
  if (people) {
    if (people->width != w || people->height != h) *people = core::LabelImage(w, h);
    uint8_t* q = people->data();
    for (size_t i = 0; i < n; ++i) q[i] = src[4 * i + 3];
  }
  return Status::Ok();
}

}  // namespace poseforest::renderer
