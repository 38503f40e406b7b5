#include "GBufferRaster.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <glm/glm.hpp>
#include <glm/gtc/matrix_inverse.hpp>
#define GL_GLEXT_PROTOTYPES
#include <GL/glcorearb.h>
#include <fmt/format.h>

#include "GBufferCommon.h"
#include "GBufferShaders.h"
#include "GLContext.h"
#include "loom/Camera.h"
#include "loom/Error.h"
#include "loom/Scene.h"
#include "loom/SurfaceKernels.h"

namespace loom {

using namespace gbuffer;

// ---------------------------------------------------------------------------
// Shaders
//
// The fragment shader does not trust interpolated attributes for values: it
// fetches the triangle's three vertices by gl_PrimitiveID (from buffer
// textures) and intersects the pixel's camera ray, built exactly as the RT
// pass builds it, jitter included, with the triangle's plane. Barycentrics,
// posW, the face normal and every attribute then follow SurfaceKernels.h
// evalSurface term by term, so the two G-buffer passes agree to float
// rounding wherever they see the same triangle: the rasterizer only decides
// visibility. Interpolated attributes serve the screen-space derivatives.
//
// Conventions: glClipControl(GL_UPPER_LEFT, GL_ZERO_TO_ONE), so window row 0
// is the top of the image as in Loom textures (no flip on readback), and a
// reversed infinite depth in 32-bit float.
//
// The GLSL sources live in shaders/, embedded by cmake/EmbedText.cmake in
// the generated GBufferShaders.h. Every stage starts with common.glsl (the
// version line, the frame block and the per-draw uniforms); outputs.glsl
// declares the fragment outputs of the consumed channels (OUT_<CHANNEL> is
// defined to the attachment index of each one), shared by geometry.frag and
// miss.frag.
//
// Miss pixels (miss.vert, miss.frag): a full-screen triangle depth-tested
// GL_EQUAL against the cleared depth (0) shades exactly the pixels no
// triangle covered, writing every miss value. Together with the geometry
// this writes each pixel of each attachment once, which is cheaper on
// llvmpipe than clearing the colour attachments first (clears are full
// memory passes too).
// ---------------------------------------------------------------------------

namespace {

// ---------------------------------------------------------------------------
// Data handed to the shaders
// ---------------------------------------------------------------------------

/// FrameBlock, std140: mat4 and vec4 members need no padding.
struct FrameGpu {
    glm::mat4 viewProj, prevViewProj, view, prevView, proj;
    glm::vec4 camOrigin, camRight, camUp, camForward, lens, viewport, jitter;
    glm::uvec4 counters;
};
static_assert(sizeof(FrameGpu) == 5 * 64 + 8 * 16);

/// A material as the per-draw uniforms uBaseColorFactor ... uFlags,
/// uUvTransform and uSampling carry it.
struct MaterialGpu {
    glm::vec4 baseColorFactor;
    glm::vec4 emissive;
    glm::vec4 params;
    glm::ivec4 textures;
    glm::uvec4 flags;
    std::array<glm::mat3x2, 4> uvTransforms;  // order of textures
    glm::uvec4 sampling;                      // order of textures: samplingBits
};

/// A texture reference's sampler as the shader's uSampling packs it. A wrap
/// value out of range repeats, as SurfaceKernels.h wrapTexel does.
uint32_t samplingBits(const TextureRef& t) {
    auto mode = [](TextureWrap w) {
        return w == TextureWrap::ClampToEdge || w == TextureWrap::MirroredRepeat ? uint32_t(w) : 0u;
    };
    static_assert(uint32_t(TextureWrap::ClampToEdge) == 1 && uint32_t(TextureWrap::MirroredRepeat) == 2);
    return mode(t.wrapS) | mode(t.wrapT) << 2 | (t.nearest ? 16u : 0u);
}

// Texture units, uniform locations and the uniform-block binding used by the shaders.
enum : GLuint {
    kUnitBaseColor = 0,
    kUnitMetalRough = 1,
    kUnitNormal = 2,
    kUnitEmissive = 3,
    kUnitPositions = 4,
    kUnitNormals = 5,
    kUnitTangents = 6,
    kUnitUvs = 7,
    kUnitTriangles = 8
};
enum : GLint {
    kLocDraw = 0,
    kLocWorld = 1,
    kLocPrevWorld = 2,
    kLocNormalMatrix = 3,
    kLocBaseColorFactor = 4,
    kLocEmissive = 5,
    kLocMaterialParams = 6,
    kLocTextures = 7,
    kLocFlags = 8,
    kLocObjRayOrigin = 9,
    kLocObjRayBasis = 10,
    kLocUvTransform = 11,  // four locations, one per texture slot
    kLocSampling = 15,
    kLocSrgbToLinear = 16  // 256 locations
};
constexpr GLuint kBindFrame = 0;

constexpr size_t kChannelCount = std::size(kChannels);

constexpr uint32_t channelBit(std::string_view name) {
    for (size_t c = 0; c < kChannelCount; ++c)
        if (name == kChannels[c].name) return 1u << c;
    return 0;
}
constexpr uint32_t kVBufferBit = channelBit(kVBuffer), kMeshIdBit = channelBit(kMeshId);
// Shader variants: bits 0..10 select channel outputs (at locations in channel
// order), plus these flags.
constexpr uint32_t kVariantAlphaTest = 1u << 16;
constexpr uint32_t kVariantMiss = 1u << 17;
constexpr uint32_t kVariantTextureSlot0 = 1u << 18;  // bits 18..21: texture slots 0..3 (order of uTextures)
constexpr uint32_t kVariantAllTextureSlots = 15u << 18;
constexpr uint32_t kVariantStatic = 1u << 22;  // the instance did not move: prevPosW = posW

[[noreturn]] void runtimeError(const std::string& what, const std::string& suggestion = {}) {
    throw Error(Error::Info{ErrorKind::Runtime, {}, "GBufferRaster", what, {}, suggestion});
}

/// GL formats of a channel's render target and readback.
struct GlFormat {
    GLenum internal, format, type;
    bool integer;
};

GlFormat glFormatOf(Format f) {
    switch (f) {
        case Format::RGBA32F: return {GL_RGBA32F, GL_RGBA, GL_FLOAT, false};
        case Format::RG32F: return {GL_RG32F, GL_RG, GL_FLOAT, false};
        case Format::R32F: return {GL_R32F, GL_RED, GL_FLOAT, false};
        case Format::RGBA32U: return {GL_RGBA32UI, GL_RGBA_INTEGER, GL_UNSIGNED_INT, true};
        case Format::RG32U: return {GL_RG32UI, GL_RG_INTEGER, GL_UNSIGNED_INT, true};
        case Format::R32U: return {GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, true};
        default: break;
    }
    runtimeError("no GL render-target format for " + std::string(formatName(f)));
}

/// The define naming a channel's output in the fragment shader ("OUT_POSW").
std::string outputDefine(const char* name) {
    std::string d = "OUT_";
    for (const char* c = name; *c; ++c) d += char(std::toupper(static_cast<unsigned char>(*c)));
    return d;
}

void checkGl(const char* where) {
    const GLenum e = glGetError();
    if (e != GL_NO_ERROR) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "0x%04X", unsigned(e));
        runtimeError(std::string("OpenGL error ") + buf + " in " + where);
    }
}

GLuint compileShader(GLenum stage, const std::string& source) {
    GLuint s = glCreateShader(stage);
    const char* src = source.c_str();
    glShaderSource(s, 1, &src, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        GLint len = 0;
        glGetShaderiv(s, GL_INFO_LOG_LENGTH, &len);
        std::string log(size_t(std::max(len, 1)), '\0');
        glGetShaderInfoLog(s, len, nullptr, log.data());
        glDeleteShader(s);
        runtimeError(std::string(stage == GL_VERTEX_SHADER ? "vertex" : "fragment") + " shader failed to compile:\n" +
                     log);
    }
    return s;
}

GLuint linkProgram(const std::string& vs, const std::string& fs) {
    GLuint v = compileShader(GL_VERTEX_SHADER, vs);
    GLuint f = 0;
    try {
        f = compileShader(GL_FRAGMENT_SHADER, fs);
    } catch (...) {
        glDeleteShader(v);
        throw;
    }
    GLuint p = glCreateProgram();
    glAttachShader(p, v);
    glAttachShader(p, f);
    glLinkProgram(p);
    glDeleteShader(v);  // flagged; freed with the program
    glDeleteShader(f);
    GLint ok = 0;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        GLint len = 0;
        glGetProgramiv(p, GL_INFO_LOG_LENGTH, &len);
        std::string log(size_t(std::max(len, 1)), '\0');
        glGetProgramInfoLog(p, len, nullptr, log.data());
        glDeleteProgram(p);
        runtimeError("shader program failed to link:\n" + log);
    }
    return p;
}

double msSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

/// Identifies an uploaded scene. The pointer alone is not enough: a frame's
/// scene arrives as a raw pointer, and a reloaded scene may reuse an address.
struct SceneKey {
    const Scene* scene = nullptr;
    size_t meshes = 0, images = 0, vertices = 0, indices = 0;
    const void* firstPositions = nullptr;
    bool operator==(const SceneKey&) const = default;
};

SceneKey keyOf(const Scene* s) {
    SceneKey k;
    if (!s) return k;
    k.scene = s;
    k.meshes = s->meshes.size();
    k.images = s->images.size();
    for (const Mesh& m : s->meshes) {
        k.vertices += m.positions.size();
        k.indices += m.indices.size();
    }
    if (!s->meshes.empty()) k.firstPositions = s->meshes.front().positions.data();
    return k;
}

}  // namespace

// ---------------------------------------------------------------------------
// GPU state
// ---------------------------------------------------------------------------

struct GBufferRaster::Gpu {
    GLContext context;
    GLint bufferAlignment = 16;  // of buffer-texture offsets
    GLint maxDrawBuffers = 8;

    struct MeshGpu {
        GLuint vao = 0, vbo = 0, ibo = 0;
        // Buffer-texture views of the vbo's arrays and of the ibo's triangles.
        GLuint positions = 0, normals = 0, tangents = 0, uvs = 0, triangles = 0;
        GLsizei indexCount = 0;
        glm::vec3 center{0.f};  // of the object-space bounds, for front-to-back ordering
    };
    struct ImageGpu {
        GLuint texels = 0;  // immutable RGBA8UI storage: the bytes as stored
    };
    SceneKey sceneKey;
    std::vector<MeshGpu> meshes;
    std::vector<ImageGpu> images;

    GLuint emptyVao = 0;
    GLuint frameUbo = 0;

    // Render targets for one set of consumed channels at one size. Channels
    // are split into groups of at most maxDrawBuffers attachments, one FBO
    // (and one geometry pass) per group, sharing the depth buffer.
    struct Group {
        GLuint fbo = 0;
        std::vector<int> channels;  // indices into kChannels; attachment i = channels[i]
    };
    uint32_t targetMask = 0, targetWidth = 0, targetHeight = 0;
    GLuint depth = 0;
    std::array<GLuint, kChannelCount> colour{};  // renderbuffer per consumed channel
    std::vector<Group> groups;

    // Programs by variant (channel bits | kVariantAlphaTest | kVariantMiss | texture slot bits).
    std::map<uint32_t, GLuint> programs;

    Gpu() {
        GLContext::Scope scope(context);
        glGetIntegerv(GL_TEXTURE_BUFFER_OFFSET_ALIGNMENT, &bufferAlignment);
        bufferAlignment = std::max(bufferAlignment, 16);
        GLint maxAttachments = 8;
        glGetIntegerv(GL_MAX_DRAW_BUFFERS, &maxDrawBuffers);
        glGetIntegerv(GL_MAX_COLOR_ATTACHMENTS, &maxAttachments);
        maxDrawBuffers = std::max(1, std::min(maxDrawBuffers, maxAttachments));

        glCreateVertexArrays(1, &emptyVao);
        glCreateBuffers(1, &frameUbo);
        glNamedBufferStorage(frameUbo, sizeof(FrameGpu), nullptr, GL_DYNAMIC_STORAGE_BIT);

        // Upper-left origin: window row 0 is the top of the image, as in
        // Loom textures, so glReadPixels writes rows in Loom's order, and
        // gl_FragCoord is in image pixels. The polygon-area sign is negated
        // with it, so glFrontFace keeps its usual meaning (ARB_clip_control,
        // core in GL 4.5, section 13.6.1). Zero-to-one depth for the
        // reversed-depth mapping in the vertex shader.
        glClipControl(GL_UPPER_LEFT, GL_ZERO_TO_ONE);
        glEnable(GL_DEPTH_TEST);
        glCullFace(GL_BACK);
        checkGl("context setup");
    }

    GLuint program(uint32_t variant) {
        auto it = programs.find(variant);
        if (it != programs.end()) return it->second;
        std::string defines;
        int location = 0;
        for (size_t c = 0; c < kChannelCount; ++c)
            if (variant & (1u << c)) defines += "#define " + outputDefine(kChannels[c].name) + " " +
                                                std::to_string(location++) + "\n";
        if (variant & kVariantAlphaTest) defines += "#define ALPHA_TEST 1\n";
        if (variant & kVariantStatic) defines += "#define STATIC_INSTANCE 1\n";
        for (int slot = 0; slot < 4; ++slot)
            if (variant & (kVariantTextureSlot0 << slot))
                defines += "#define TEXTURE_SLOT_" + std::to_string(slot) + " 1\n";
        const bool miss = variant & kVariantMiss;
        // Each file's text follows a line break, so that one file's last line
        // and the next one's first stay apart. "#version" must come first:
        // defines go right after the common block's version line.
        const auto part = [](const char* text) { return std::string(1, '\n') + text; };
        std::string common = part(shaders::kCommonGlsl);
        const size_t afterVersion = common.find('\n', common.find("#version")) + 1;
        common.insert(afterVersion, defines);
        const std::string outputs = common + part(shaders::kOutputsGlsl);
        GLuint p = miss ? linkProgram(common + part(shaders::kMissVert), outputs + part(shaders::kMissFrag))
                        : linkProgram(common + part(shaders::kGeometryVert), outputs + part(shaders::kGeometryFrag));
        if (!miss) {
            // The shader's sRGB decoding table, computed by the CPU's code.
            std::array<float, 256> srgbTable{};
            for (size_t b = 0; b < srgbTable.size(); ++b) srgbTable[b] = srgbToLinear(float(b) / 255.f);
            glProgramUniform1fv(p, kLocSrgbToLinear, GLsizei(srgbTable.size()), srgbTable.data());
        }
        programs.emplace(variant, p);
        return p;
    }

    void freeScene() {
        for (MeshGpu& m : meshes) {
            for (GLuint t : {m.positions, m.normals, m.tangents, m.uvs, m.triangles})
                if (t) glDeleteTextures(1, &t);
            glDeleteVertexArrays(1, &m.vao);
            glDeleteBuffers(1, &m.vbo);
            glDeleteBuffers(1, &m.ibo);
        }
        for (ImageGpu& i : images)
            if (i.texels) glDeleteTextures(1, &i.texels);
        meshes.clear();
        images.clear();
        sceneKey = {};
    }

    GLintptr aligned(GLintptr offset) const {
        return (offset + bufferAlignment - 1) / bufferAlignment * bufferAlignment;
    }

    /// A buffer texture viewing bytes [offset, offset + size) of a buffer.
    static GLuint bufferTexture(GLenum format, GLuint buffer, GLintptr offset, GLsizeiptr size) {
        GLuint t = 0;
        glCreateTextures(GL_TEXTURE_BUFFER, 1, &t);
        glTextureBufferRange(t, format, buffer, offset, size);
        return t;
    }

    void uploadScene(const Scene& scene) {
        freeScene();
        meshes.resize(scene.meshes.size());
        for (size_t mi = 0; mi < scene.meshes.size(); ++mi) {
            const Mesh& mesh = scene.meshes[mi];
            MeshGpu& g = meshes[mi];
            const size_t n = mesh.positions.size();
            if (n == 0 || mesh.indices.size() < 3) continue;
            // The scene guarantees full attribute arrays; pad defensively so a
            // malformed mesh reads defaults rather than past a buffer's end.
            auto padded = [n](const auto& src, auto def) {
                std::vector<std::decay_t<decltype(def)>> v(src.begin(), src.end());
                v.resize(n, def);
                return v;
            };
            const auto normals = padded(mesh.normals, glm::vec3(0.f, 0.f, 1.f));
            const auto tangents = padded(mesh.tangents, glm::vec4(1.f, 0.f, 0.f, 1.f));
            const auto uvs = padded(mesh.uvs, glm::vec2(0.f));
            // One vertex buffer holds the four arrays at offsets aligned for
            // buffer textures (GL 4.5, section 8.9), one view per array.
            const GLsizeiptr positionsBytes = GLsizeiptr(n * sizeof(glm::vec3));
            const GLsizeiptr normalsBytes = GLsizeiptr(n * sizeof(glm::vec3));
            const GLsizeiptr tangentsBytes = GLsizeiptr(n * sizeof(glm::vec4));
            const GLsizeiptr uvsBytes = GLsizeiptr(n * sizeof(glm::vec2));
            const GLintptr normalsOffset = aligned(positionsBytes);
            const GLintptr tangentsOffset = aligned(normalsOffset + normalsBytes);
            const GLintptr uvsOffset = aligned(tangentsOffset + tangentsBytes);
            glCreateBuffers(1, &g.vbo);
            glNamedBufferStorage(g.vbo, uvsOffset + uvsBytes, nullptr, GL_DYNAMIC_STORAGE_BIT);
            glNamedBufferSubData(g.vbo, 0, positionsBytes, mesh.positions.data());
            glNamedBufferSubData(g.vbo, normalsOffset, normalsBytes, normals.data());
            glNamedBufferSubData(g.vbo, tangentsOffset, tangentsBytes, tangents.data());
            glNamedBufferSubData(g.vbo, uvsOffset, uvsBytes, uvs.data());
            // RGB32F buffer textures: core since GL 4.0 (ARB_texture_buffer_object_rgb32).
            g.positions = bufferTexture(GL_RGB32F, g.vbo, 0, positionsBytes);
            g.normals = bufferTexture(GL_RGB32F, g.vbo, normalsOffset, normalsBytes);
            g.tangents = bufferTexture(GL_RGBA32F, g.vbo, tangentsOffset, tangentsBytes);
            g.uvs = bufferTexture(GL_RG32F, g.vbo, uvsOffset, uvsBytes);
            Bounds b;
            for (const glm::vec3& p : mesh.positions) b.extend(p);
            g.center = b.center();
            g.indexCount = GLsizei(mesh.indices.size() / 3 * 3);
            const GLsizeiptr indicesBytes = GLsizeiptr(size_t(g.indexCount) * sizeof(uint32_t));
            glCreateBuffers(1, &g.ibo);
            glNamedBufferStorage(g.ibo, indicesBytes, mesh.indices.data(), 0);
            // Seen as RGB32UI, texel i of the index buffer is triangle i's three indices.
            g.triangles = bufferTexture(GL_RGB32UI, g.ibo, 0, indicesBytes);

            glCreateVertexArrays(1, &g.vao);
            glVertexArrayVertexBuffer(g.vao, 0, g.vbo, 0, sizeof(glm::vec3));
            glEnableVertexArrayAttrib(g.vao, 0);
            glVertexArrayAttribFormat(g.vao, 0, 3, GL_FLOAT, GL_FALSE, 0);
            glVertexArrayAttribBinding(g.vao, 0, 0);
            glVertexArrayVertexBuffer(g.vao, 1, g.vbo, normalsOffset, sizeof(glm::vec3));
            glEnableVertexArrayAttrib(g.vao, 1);
            glVertexArrayAttribFormat(g.vao, 1, 3, GL_FLOAT, GL_FALSE, 0);
            glVertexArrayAttribBinding(g.vao, 1, 1);
            glVertexArrayElementBuffer(g.vao, g.ibo);
        }

        // Images a material samples, uploaded once each whatever their slots
        // (the shader decodes sRGB per slot).
        std::vector<uint8_t> used(scene.images.size(), 0);
        for (const Material& m : scene.materials)
            for (const TextureRef* t :
                 {&m.baseColorTexture, &m.emissiveTexture, &m.metallicRoughnessTexture, &m.normalTexture})
                if (t->image >= 0 && size_t(t->image) < used.size()) used[size_t(t->image)] = 1;
        images.resize(scene.images.size());
        glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
        glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
        for (size_t i = 0; i < scene.images.size(); ++i) {
            const SceneImage& img = scene.images[i];
            if (!used[i] || img.width == 0 || img.height == 0 || img.texels.size() < size_t(img.width) * img.height)
                continue;
            // Row 0 of a SceneImage is glTF uv.y = 0, and GL's first row is t = 0:
            // uploaded as is, no flip. One level: sampleTexture has no mipmaps.
            ImageGpu& g = images[i];
            glCreateTextures(GL_TEXTURE_2D, 1, &g.texels);
            glTextureStorage2D(g.texels, 1, GL_RGBA8UI, GLsizei(img.width), GLsizei(img.height));
            glTextureSubImage2D(g.texels, 0, 0, 0, GLsizei(img.width), GLsizei(img.height), GL_RGBA_INTEGER,
                                GL_UNSIGNED_BYTE, img.texels.data());
            // An integer texture with a linear filter is incomplete and reads as 0 (GL 4.5, section 8.17),
            // even through texelFetch.
            glTextureParameteri(g.texels, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
            glTextureParameteri(g.texels, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
        }
        checkGl("scene upload");
        sceneKey = keyOf(&scene);
    }

    void freeTargets() {
        for (Group& g : groups) glDeleteFramebuffers(1, &g.fbo);
        groups.clear();
        for (GLuint& rb : colour)
            if (rb) {
                glDeleteRenderbuffers(1, &rb);
                rb = 0;
            }
        if (depth) glDeleteRenderbuffers(1, &depth);
        depth = 0;
        targetMask = targetWidth = targetHeight = 0;
    }

    void ensureTargets(uint32_t mask, uint32_t width, uint32_t height) {
        if (mask == targetMask && width == targetWidth && height == targetHeight) return;
        freeTargets();
        // 32-bit float depth, reversed (see the vertex shader).
        glCreateRenderbuffers(1, &depth);
        glNamedRenderbufferStorage(depth, GL_DEPTH_COMPONENT32F, GLsizei(width), GLsizei(height));
        for (size_t c = 0; c < kChannelCount; ++c) {
            if (!(mask & (1u << c))) continue;
            glCreateRenderbuffers(1, &colour[c]);
            glNamedRenderbufferStorage(colour[c], glFormatOf(kChannels[c].format).internal, GLsizei(width),
                                       GLsizei(height));
            if (groups.empty() || int(groups.back().channels.size()) == maxDrawBuffers) groups.emplace_back();
            Group& g = groups.back();
            g.channels.push_back(int(c));
        }
        // Render targets are where a large frame runs out of GL memory: say so with the size, not as a bare code.
        const size_t targetBytes = size_t(width) * height * 4 * (1 + size_t(std::popcount(mask)) * 4);
        if (const GLenum e = glGetError(); e == GL_OUT_OF_MEMORY)
            runtimeError(fmt::format("out of GL memory for the {}x{} render targets (about {} MiB)", width, height,
                                     targetBytes >> 20),
                         "render at a smaller size");
        else if (e != GL_NO_ERROR)
            runtimeError(fmt::format("OpenGL error 0x{:04X} creating the {}x{} render targets", unsigned(e), width,
                                     height));
        for (Group& g : groups) {
            glCreateFramebuffers(1, &g.fbo);
            std::vector<GLenum> buffers;
            for (size_t i = 0; i < g.channels.size(); ++i) {
                glNamedFramebufferRenderbuffer(g.fbo, GLenum(GL_COLOR_ATTACHMENT0 + i), GL_RENDERBUFFER,
                                               colour[size_t(g.channels[i])]);
                buffers.push_back(GLenum(GL_COLOR_ATTACHMENT0 + i));
            }
            glNamedFramebufferRenderbuffer(g.fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
            glNamedFramebufferDrawBuffers(g.fbo, GLsizei(buffers.size()), buffers.data());
            const GLenum status = glCheckNamedFramebufferStatus(g.fbo, GL_DRAW_FRAMEBUFFER);
            if (status != GL_FRAMEBUFFER_COMPLETE) {
                char buf[32];
                std::snprintf(buf, sizeof buf, "0x%04X", unsigned(status));
                runtimeError(fmt::format("the {}x{} render targets are incomplete (framebuffer status {}, about {} MiB)",
                                         width, height, buf, targetBytes >> 20),
                             "render at a smaller size");
            }
        }
        checkGl("render targets");
        targetMask = mask;
        targetWidth = width;
        targetHeight = height;
    }
};

// ---------------------------------------------------------------------------
// The pass
// ---------------------------------------------------------------------------

GBufferRaster::GBufferRaster() = default;

GBufferRaster::~GBufferRaster() {
    // Destroying the context frees every GL object; nothing needs to be current.
    mGpu.reset();
}

void GBufferRaster::reflect(Reflection& r, const CompileInfo&) const { reflectChannels(r); }

void GBufferRaster::declareParams(ParamList& p) {
    const gbuffer::Visibility defaults;
    p.addEnum("cullMode", &mVisibility.cullMode, defaults.cullMode, {"none", "back"})
        .doc("cull back faces of single-sided materials (double-sided ones are always drawn)");
    p.add("alphaTest", &mVisibility.alphaTest, defaults.alphaTest)
        .doc(
            "alphaMode MASK discards fragments where alpha < alphaCutoff; BLEND is stochastic transparency (kept "
            "with probability alpha, decided as in GBufferRT); false: every material opaque");
    p.add("specialize", &mSpecialize, true)
        .doc(
            "a shader variant per draw without what its material and instance do not need: texture slots the "
            "material lacks, alpha testing for opaque materials, the previous-position transform for an instance "
            "that did not move; the output is the same bit for bit. false: one generic variant for every draw, "
            "for comparison");
}

std::vector<std::string> GBufferRaster::skippedWork() const {
    if (!mSpecialize || !mScene) return {};
    const SceneFeatures& f = mScene->features();
    std::vector<std::string> lines;
    if (!f.textures)
        lines.push_back("texture sampling: no material has a texture");
    else
        lines.push_back("texture sampling of the slots a material lacks: a shader variant per material");
    if (!f.alphaTested)
        lines.push_back("alpha testing: no material is alpha-tested");
    else if (mVisibility.alphaTest)
        lines.push_back("alpha testing of opaque materials: a shader variant per material");
    if (!f.animatedNodes)
        lines.push_back("previous positions of surfaces: no node is animated (motion vectors are the camera's alone)");
    return lines;
}

GBufferRaster::Gpu& GBufferRaster::gpu() {
    if (!mGpu) mGpu = std::make_unique<Gpu>();
    return *mGpu;
}

void GBufferRaster::compile(const CompileInfo&) {
    // Create the context now, so a machine without GL 4.5 fails when the
    // graph is compiled rather than on its first frame.
    gpu();
}

void GBufferRaster::setScene(const std::shared_ptr<const Scene>& scene) {
    mScene = scene;
    if (!scene) return;
    Gpu& g = gpu();
    GLContext::Scope current(g.context);
    if (!(g.sceneKey == keyOf(scene.get()))) g.uploadScene(*scene);
}

void GBufferRaster::execute(PassContext& ctx) {
    const Scene* scene = ctx.scene() ? ctx.scene() : mScene.get();
    if (!scene)
        throwBadInput(ctx.passName(), "GBufferRaster needs a scene, and the graph was run without one",
                      "a scene given with --scene", "render with `loom render --scene <file.gltf> ...`");

    // Consumed channels and the frame size (every channel is frame-sized).
    std::array<Texture*, kChannelCount> outputs{};
    uint32_t mask = 0, width = 0, height = 0;
    for (size_t c = 0; c < kChannelCount; ++c) {
        outputs[c] = ctx.output(kChannels[c].name);
        if (!outputs[c]) continue;
        if (mask != 0 && (outputs[c]->width() != width || outputs[c]->height() != height))
            runtimeError("channels have different sizes (" + std::string(kChannels[c].name) + " is " +
                         std::to_string(outputs[c]->width()) + "x" + std::to_string(outputs[c]->height()) + ")");
        width = outputs[c]->width();
        height = outputs[c]->height();
        mask |= 1u << c;
    }
    if (mask == 0 || width == 0 || height == 0) return;

    Camera camera = ctx.camera() ? *ctx.camera() : scene->camera;
    camera.aspect = float(width) / float(height);

    Gpu& g = gpu();
    GLContext::Scope current(g.context);
    auto t0 = std::chrono::steady_clock::now();
    if (!(g.sceneKey == keyOf(scene))) {
        g.uploadScene(*scene);
        ctx.stats().set("uploadMs", msSince(t0));
        t0 = std::chrono::steady_clock::now();
    }
    // meshId is vbuffer's first component: with both consumed, it is read
    // from vbuffer's attachment (GL_RED_INTEGER) rather than rendered, which
    // saves an attachment and, at 9 channels, a second geometry pass.
    const bool meshIdFromVBuffer = (mask & kVBufferBit) && (mask & kMeshIdBit);
    const uint32_t renderMask = meshIdFromVBuffer ? mask & ~kMeshIdBit : mask;
    g.ensureTargets(renderMask, width, height);

    // Per-frame data: the camera, and materials (small, and editable between
    // frames). Instance transforms are read per draw (animation moves them).
    FrameGpu frame{};
    frame.view = camera.view();
    frame.prevView = camera.prevView();
    frame.proj = camera.proj();
    frame.viewProj = frame.proj * frame.view;
    frame.prevViewProj = frame.proj * frame.prevView;
    frame.camOrigin = glm::vec4(camera.position(), 1.f);
    frame.camRight = glm::vec4(camera.right(), 0.f);
    frame.camUp = glm::vec4(camera.up(), 0.f);
    frame.camForward = glm::vec4(camera.forward(), 0.f);
    frame.lens = glm::vec4(std::tan(0.5f * camera.fovY), camera.aspect, camera.nearZ, 0.f);
    frame.viewport = glm::vec4(float(width), float(height), 0.f, 0.f);
    frame.jitter = glm::vec4(camera.jitterNdcOffset(width, height), camera.jitter);
    frame.counters = glm::uvec4(uint32_t(ctx.frameIndex()), 0u, 0u, 0u);
    glNamedBufferSubData(g.frameUbo, 0, sizeof frame, &frame);

    // The last entry is a default material for meshes whose index is out of range.
    std::vector<MaterialGpu> materials(scene->materials.size() + 1);
    for (size_t i = 0; i < materials.size(); ++i) {
        const Material m = i < scene->materials.size() ? scene->materials[i] : Material{};
        // A texture that was not uploaded (bad index, empty image) is treated as absent.
        auto tex = [&](const TextureRef& t) {
            return t.image >= 0 && size_t(t.image) < g.images.size() && g.images[size_t(t.image)].texels ? t.image : -1;
        };
        materials[i].baseColorFactor = m.baseColorFactor;
        materials[i].emissive = glm::vec4(m.emissiveFactor, m.normalScale);
        materials[i].params = glm::vec4(m.metallicFactor, m.roughnessFactor, m.alphaCutoff, 0.f);
        materials[i].textures = glm::ivec4(tex(m.baseColorTexture), tex(m.metallicRoughnessTexture),
                                           tex(m.normalTexture), tex(m.emissiveTexture));
        const TextureRef* slots[4] = {&m.baseColorTexture, &m.metallicRoughnessTexture, &m.normalTexture,
                                      &m.emissiveTexture};
        for (size_t k = 0; k < 4; ++k) {
            materials[i].uvTransforms[k] = slots[k]->transform;
            materials[i].sampling[int(k)] = samplingBits(*slots[k]);
        }
        materials[i].flags = glm::uvec4(m.doubleSided ? 1u : 0u, m.alphaMode == AlphaMode::Mask ? 1u : 0u,
                                        m.alphaMode == AlphaMode::Blend ? 1u : 0u, 0u);
    }

    glBindBufferBase(GL_UNIFORM_BUFFER, kBindFrame, g.frameUbo);
    glViewport(0, 0, GLsizei(width), GLsizei(height));

    const bool cullBack = mVisibility.cullMode == CullMode::Back;
    // World-space ray direction of image position ndc = rayBasis * (1, ndc.x, ndc.y).
    const float tanHalfFovY = std::tan(0.5f * camera.fovY);
    const glm::mat3 rayBasis(camera.forward(), camera.right() * (tanHalfFovY * camera.aspect),
                             camera.up() * tanHalfFovY);
    // Front to back, so the early depth test rejects hidden fragments
    // before the (costly) fragment shader runs on llvmpipe.
    std::vector<std::pair<float, uint32_t>> order;
    order.reserve(scene->instances.size());
    for (size_t i = 0; i < scene->instances.size(); ++i) {
        const Instance& inst = scene->instances[i];
        if (inst.mesh >= g.meshes.size() || !g.meshes[inst.mesh].vao || !inst.visible()) continue;
        const glm::vec3 c = glm::vec3(inst.world * glm::vec4(g.meshes[inst.mesh].center, 1.f));
        order.emplace_back(glm::dot(c - camera.position(), camera.forward()), uint32_t(i));
    }
    std::sort(order.begin(), order.end());

    uint32_t drawCalls = 0;
    for (size_t gi = 0; gi < g.groups.size(); ++gi) {
        const Gpu::Group& group = g.groups[gi];
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, group.fbo);
        uint32_t groupMask = 0;
        for (int c : group.channels) groupMask |= 1u << c;
        // The first group lays down depth; later groups shade exactly the
        // fragments that won it (same invariant positions, GL_EQUAL).
        if (gi == 0) {
            const float clearDepth = 0.f;  // reversed depth: 0 is infinitely far
            glDepthMask(GL_TRUE);  // clears obey the write mask (GL 4.5, section 17.4.3)
            glClearNamedFramebufferfv(group.fbo, GL_DEPTH, 0, &clearDepth);
            glDepthFunc(GL_GREATER);
        } else {
            glDepthFunc(GL_EQUAL);
            glDepthMask(GL_FALSE);
        }

        GLuint boundProgram = 0;
        int cullState = -1;
        GLenum frontFace = 0;
        for (const auto& [viewDepth, i] : order) {
            const Instance& inst = scene->instances[i];
            const Gpu::MeshGpu& mesh = g.meshes[inst.mesh];
            const uint32_t matIndex = std::min<uint32_t>(scene->meshes[inst.mesh].material,
                                                         uint32_t(scene->materials.size()));
            const MaterialGpu& mat = materials[matIndex];
            const bool doubleSided = mat.flags.x != 0;
            const bool alphaTested = mVisibility.alphaTest && (mat.flags.y != 0 || mat.flags.z != 0);

            // The variant without what this draw does not need (specialize), else the generic one.
            uint32_t variant = groupMask;
            if (mSpecialize) {
                for (int slot = 0; slot < 4; ++slot)
                    if (mat.textures[slot] >= 0) variant |= kVariantTextureSlot0 << slot;
                if (alphaTested) variant |= kVariantAlphaTest;
                if (inst.prevWorld == inst.world) variant |= kVariantStatic;
            } else {
                variant |= kVariantAllTextureSlots | (mVisibility.alphaTest ? kVariantAlphaTest : 0u);
            }
            const GLuint program = g.program(variant);
            if (program != boundProgram) {
                glUseProgram(program);
                boundProgram = program;
            }
            const int cull = cullBack && !doubleSided ? 1 : 0;
            if (cull != cullState) {
                cull ? glEnable(GL_CULL_FACE) : glDisable(GL_CULL_FACE);
                cullState = cull;
            }
            // A mirroring transform reverses the winding; glTF counts faces
            // as front by their world-space orientation (and so does evalSurface).
            const GLenum ff = glm::determinant(glm::mat3(inst.world)) < 0.f ? GL_CW : GL_CCW;
            if (ff != frontFace) {
                glFrontFace(ff);
                frontFace = ff;
            }
            glBindVertexArray(mesh.vao);
            glBindTextureUnit(kUnitPositions, mesh.positions);
            glBindTextureUnit(kUnitNormals, mesh.normals);
            glBindTextureUnit(kUnitTangents, mesh.tangents);
            glBindTextureUnit(kUnitUvs, mesh.uvs);
            glBindTextureUnit(kUnitTriangles, mesh.triangles);
            auto bindTex = [&](GLuint unit, int index) {
                glBindTextureUnit(unit, index >= 0 ? g.images[size_t(index)].texels : 0);
            };
            bindTex(kUnitBaseColor, mat.textures.x);
            bindTex(kUnitMetalRough, mat.textures.y);
            bindTex(kUnitNormal, mat.textures.z);
            bindTex(kUnitEmissive, mat.textures.w);
            const glm::mat4 worldInverse = glm::inverse(inst.world);
            const glm::mat3 normalMatrix = glm::inverseTranspose(glm::mat3(inst.world));
            glUniform4ui(kLocDraw, GLuint(i), matIndex, 0u, 0u);
            glUniformMatrix4fv(kLocWorld, 1, GL_FALSE, &inst.world[0][0]);
            glUniformMatrix4fv(kLocPrevWorld, 1, GL_FALSE, &inst.prevWorld[0][0]);
            glUniformMatrix3fv(kLocNormalMatrix, 1, GL_FALSE, &normalMatrix[0][0]);
            glUniform4fv(kLocBaseColorFactor, 1, &mat.baseColorFactor[0]);
            glUniform4fv(kLocEmissive, 1, &mat.emissive[0]);
            glUniform4fv(kLocMaterialParams, 1, &mat.params[0]);
            glUniform4iv(kLocTextures, 1, &mat.textures[0]);
            glUniform4uiv(kLocFlags, 1, &mat.flags[0]);
            glUniformMatrix3x2fv(kLocUvTransform, 4, GL_FALSE, &mat.uvTransforms[0][0][0]);
            glUniform4uiv(kLocSampling, 1, &mat.sampling[0]);
            const glm::vec3 objOrigin = glm::vec3(worldInverse * glm::vec4(camera.position(), 1.f));
            const glm::mat3 objBasis = glm::mat3(worldInverse) * rayBasis;
            glUniform3fv(kLocObjRayOrigin, 1, &objOrigin[0]);
            glUniformMatrix3fv(kLocObjRayBasis, 1, GL_FALSE, &objBasis[0][0]);
            glDrawElements(GL_TRIANGLES, mesh.indexCount, GL_UNSIGNED_INT, nullptr);
            ++drawCalls;
        }

        // Miss values where no triangle was drawn (see shaders/miss.frag).
        glUseProgram(g.program(groupMask | kVariantMiss));
        glDisable(GL_CULL_FACE);
        glDepthFunc(GL_EQUAL);
        glDepthMask(GL_FALSE);
        glBindVertexArray(g.emptyVao);
        glDrawArrays(GL_TRIANGLES, 0, 3);
    }
    glFinish();  // so the timings separate rendering from readback
    checkGl("rendering");
    const double renderMs = msSince(t0);

    // Readback into the graph's textures. Rows are 64-byte aligned in Loom
    // textures: GL_PACK_ROW_LENGTH (in pixels) makes GL write at that pitch.
    const auto t1 = std::chrono::steady_clock::now();
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    for (const Gpu::Group& group : g.groups) {
        glBindFramebuffer(GL_READ_FRAMEBUFFER, group.fbo);
        for (size_t slot = 0; slot < group.channels.size(); ++slot) {
            Texture* t = outputs[size_t(group.channels[slot])];
            const GlFormat f = glFormatOf(t->format());
            glNamedFramebufferReadBuffer(group.fbo, GLenum(GL_COLOR_ATTACHMENT0 + slot));
            glPixelStorei(GL_PACK_ROW_LENGTH, GLint(t->rowPitch() / formatInfo(t->format()).bytesPerPixel));
            glReadPixels(0, 0, GLsizei(width), GLsizei(height), f.format, f.type, t->data());
            if (meshIdFromVBuffer && (1u << group.channels[slot]) == kVBufferBit) {
                Texture* ids = outputs[size_t(std::countr_zero(kMeshIdBit))];
                glPixelStorei(GL_PACK_ROW_LENGTH, GLint(ids->rowPitch() / sizeof(uint32_t)));
                glReadPixels(0, 0, GLsizei(width), GLsizei(height), GL_RED_INTEGER, GL_UNSIGNED_INT, ids->data());
            }
        }
    }
    glPixelStorei(GL_PACK_ROW_LENGTH, 0);
    checkGl("readback");
    ctx.stats().set("renderMs", renderMs);
    ctx.stats().set("readbackMs", msSince(t1));
    ctx.stats().set("drawCalls", double(drawCalls));
    ctx.stats().set("geometryPasses", double(g.groups.size()));
}

}  // namespace loom
