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
// ---------------------------------------------------------------------------

namespace {

constexpr char kShaderCommon[] = R"glsl(
#version 450 core

// Per-frame camera data (std140; FrameGpu on the C++ side).
layout(std140, binding = 0) uniform FrameBlock {
    mat4 viewProj;      // unjittered
    mat4 prevViewProj;  // unjittered, last frame's camera
    mat4 view;
    mat4 prevView;
    mat4 proj;
    vec4 camOrigin;
    vec4 camRight;
    vec4 camUp;
    vec4 camForward;
    vec4 lens;          // x: tan(fovY / 2), y: aspect, z: nearZ
    vec4 viewport;      // x: width, y: height (pixels)
    vec4 jitter;        // xy: NDC offset (Camera::jitterNdcOffset), zw: jitter in pixels
    uvec4 counters;     // x: frame index (low 32 bits), for stochastic transparency
} uFrame;

// Per draw: x = instance id, y = material index; the instance's transforms.
// Plain uniforms rather than a storage buffer: helper invocations need them
// too (see the derivatives in the fragment shader).
layout(location = 0) uniform uvec4 uDraw;
layout(location = 1) uniform mat4 uWorld;
layout(location = 2) uniform mat4 uPrevWorld;
layout(location = 3) uniform mat3 uNormalMatrix;  // inverse transpose of uWorld's upper 3x3
)glsl";

// Fragment outputs of the consumed channels (OUT_<CHANNEL> is defined to the
// attachment index of each one), shared by the geometry and miss shaders.
constexpr char kFragmentOutputs[] = R"glsl(
#ifdef OUT_POSW
layout(location = OUT_POSW) out vec4 oPosW;
#endif
#ifdef OUT_NORMW
layout(location = OUT_NORMW) out vec4 oNormW;
#endif
#ifdef OUT_FACENORMALW
layout(location = OUT_FACENORMALW) out vec4 oFaceNormalW;
#endif
#ifdef OUT_LINEARZ
layout(location = OUT_LINEARZ) out vec2 oLinearZ;
#endif
#ifdef OUT_PNFWIDTH
layout(location = OUT_PNFWIDTH) out vec2 oPnFwidth;
#endif
#ifdef OUT_MVEC
layout(location = OUT_MVEC) out vec2 oMvec;
#endif
#ifdef OUT_ALBEDO
layout(location = OUT_ALBEDO) out vec4 oAlbedo;
#endif
#ifdef OUT_SPECALBEDO
layout(location = OUT_SPECALBEDO) out vec4 oSpecAlbedo;
#endif
#ifdef OUT_EMISSION
layout(location = OUT_EMISSION) out vec4 oEmission;
#endif
#ifdef OUT_VBUFFER
layout(location = OUT_VBUFFER) out uvec4 oVBuffer;
#endif
#ifdef OUT_MESHID
layout(location = OUT_MESHID) out uint oMeshId;
#endif
)glsl";

constexpr char kGeometryVS[] = R"glsl(
layout(location = 0) in vec3 aPosition;
layout(location = 1) in vec3 aNormal;
out vec3 vObjPos;
out vec3 vPosW;
out vec3 vNormalW;

// Several geometry passes (more channels than draw buffers) depth-test
// against the first pass with GL_EQUAL, which needs bit-identical depth
// across programs (GLSL 4.50, section 4.8.1).
invariant gl_Position;

void main() {
    const vec4 posW = uWorld * vec4(aPosition, 1.0);
    vec4 clip = uFrame.viewProj * posW;
    // Sub-pixel jitter: an NDC offset, hence scaled by w in clip space.
    clip.xy += uFrame.jitter.xy * clip.w;
    // Reversed, infinite depth: z_ndc = nearZ / viewDepth with the
    // GL_ZERO_TO_ONE clip control. Float depth keeps a constant relative
    // precision at every distance this way, and there is no far plane (the
    // RT pass has none either). clip.w is the view depth for Camera::proj.
    gl_Position = vec4(clip.xy, uFrame.lens.z, clip.w);
    vObjPos = aPosition;
    vPosW = posW.xyz;
    vNormalW = uNormalMatrix * aNormal;
}
)glsl";

constexpr char kGeometryFS[] = R"glsl(
// The drawn material (MaterialGpu on the C++ side).
layout(location = 4) uniform vec4 uBaseColorFactor;
layout(location = 5) uniform vec4 uEmissive;      // xyz: emissiveFactor, w: normalScale
layout(location = 6) uniform vec4 uMaterialParams; // x: metallic, y: roughness, z: alphaCutoff
layout(location = 7) uniform ivec4 uTextures;      // baseColor, metallicRoughness, normal, emissive (-1 = none)
layout(location = 8) uniform uvec4 uFlags;         // x: doubleSided, y: alpha mask, z: alpha blend

// The drawn mesh's vertex arrays and triangles, as buffer textures (views of
// its buffers). Buffer textures rather than storage buffers: llvmpipe
// gathers texel fetches for a whole SIMD vector, while it loads storage
// buffers at divergent offsets one lane at a time, and not at all for
// helper invocations.
layout(binding = 4) uniform samplerBuffer uPositions;   // RGB32F
layout(binding = 5) uniform samplerBuffer uNormals;     // RGB32F
layout(binding = 6) uniform samplerBuffer uTangents;    // RGBA32F
layout(binding = 7) uniform samplerBuffer uUvs;         // RG32F
layout(binding = 8) uniform usamplerBuffer uTriangles;  // RGB32UI: a triangle's three indices

// Material images as stored (RGBA8UI: the bytes themselves), read with
// texelFetch and filtered here as SurfaceKernels.h sampleTexture does, so the
// two agree to float rounding: GL's own filtering weighs texels with a few
// bits of precision, and llvmpipe decodes sRGB approximately (0.7 % off).
layout(binding = 0) uniform usampler2D uBaseColorTex;  // sRGB
layout(binding = 1) uniform usampler2D uMetalRoughTex; // linear
layout(binding = 2) uniform usampler2D uNormalTex;     // linear
layout(binding = 3) uniform usampler2D uEmissiveTex;   // sRGB
// SurfaceKernels.h srgbToLinear(byte / 255) for each byte, computed by it
// (Gpu::program). A uniform array: on llvmpipe a lookup in it costs less than
// a buffer-texture fetch (with a buffer texture, the pass took 1.7 times as
// long on data/scenes/materials).
layout(location = 16) uniform float uSrgbToLinear[256];

// Interpolated attributes: for derivatives and grazing rays only.
in vec3 vObjPos;
in vec3 vPosW;
in vec3 vNormalW;

// The camera ray in the drawn instance's object space: origin, and the
// direction of image position ndc as uObjRayBasis * (1, ndc.x, ndc.y)
// (CameraKernels.h cameraRayDir through the inverse world matrix).
layout(location = 9) uniform vec3 uObjRayOrigin;
layout(location = 10) uniform mat3 uObjRayBasis;
// Per texture slot (order of uTextures), its TextureRef: the
// KHR_texture_transform as the affine map uv' = uUvTransform[slot] * (u, v, 1),
// and its sampler (bits 0-1 wrapS, 2-3 wrapT as TextureWrap, bit 4 nearest).
layout(location = 11) uniform mat3x2 uUvTransform[4];
layout(location = 15) uniform uvec4 uSampling;


vec3 fetchPosition(uint i) { return texelFetch(uPositions, int(i)).xyz; }
vec3 fetchNormal(uint i) { return texelFetch(uNormals, int(i)).xyz; }

// i mod n in [0, n), for |i| <= 2^24 + 1. Without an integer division (GLSL
// leaves % undefined for negative operands, and llvmpipe divides integers one
// lane at a time): the float quotient is off by at most one, which is
// corrected; the clamp only guards the texel fetch.
int floorMod(int i, int n) {
    int m = i - n * int(floor(float(i) / float(n)));
    m += m < 0 ? n : (m >= n ? -n : 0);
    return clamp(m, 0, n - 1);
}

// SurfaceKernels.h wrapTexel (GL 4.5, table 8.20) of texels i and i + 1.
ivec2 wrapTexels(int i, int n, uint mode) {
    if (mode == 1u) return clamp(ivec2(i, i + 1), 0, n - 1);
    const int period = mode == 2u ? 2 * n : n;
    const int m0 = floorMod(i, period);
    const ivec2 m = ivec2(m0, m0 + 1 == period ? 0 : m0 + 1);
    return mode == 2u ? mix(m, period - 1 - m, greaterThanEqual(m, ivec2(n))) : m;
}

// SurfaceKernels.h sampleTexture's texelCoord.
float texelCoord(float c) {
    const float limit = 16777216.0;
    return !(c >= -limit) ? -limit : (c > limit ? limit : c);
}

// A texel as SurfaceKernels.h sampleTexture's fetch decodes it: byte / 255,
// and sRGB colour through srgbToLinear's values.
vec4 fetchTexel(usampler2D tex, int x, int y, bool srgb) {
    const uvec4 t = texelFetch(tex, ivec2(x, y), 0);
    if (!srgb) return vec4(t) / 255.0;
    return vec4(uSrgbToLinear[t.r], uSrgbToLinear[t.g], uSrgbToLinear[t.b], float(t.a) / 255.0);
}

// glm::mix's formula, x * (1 - a) + y * a, written out.
vec4 lerp(vec4 x, vec4 y, float a) { return x * (1.0 - a) + y * a; }

// SurfaceKernels.h sampleTexture for texture slot `slot`, term by term.
vec4 sampleTexture(usampler2D tex, int slot, vec2 uv, bool srgb) {
    const mat3x2 m = uUvTransform[slot];
    uv = vec2(m[0][0] * uv.x + m[1][0] * uv.y + m[2][0], m[0][1] * uv.x + m[1][1] * uv.y + m[2][1]);
    const uint sampling = uSampling[slot];
    const uint wrapS = sampling & 3u, wrapT = (sampling >> 2) & 3u;
    const ivec2 size = textureSize(tex, 0);
    if ((sampling & 16u) != 0u) {
        const int x = int(floor(texelCoord(uv.x * float(size.x))));
        const int y = int(floor(texelCoord(uv.y * float(size.y))));
        return fetchTexel(tex, wrapTexels(x, size.x, wrapS).x, wrapTexels(y, size.y, wrapT).x, srgb);
    }
    const float fx = texelCoord(uv.x * float(size.x) - 0.5);
    const float fy = texelCoord(uv.y * float(size.y) - 0.5);
    const float x0f = floor(fx), y0f = floor(fy);
    const float tx = fx - x0f, ty = fy - y0f;
    const ivec2 xs = wrapTexels(int(x0f), size.x, wrapS), ys = wrapTexels(int(y0f), size.y, wrapT);
    return lerp(lerp(fetchTexel(tex, xs.x, ys.x, srgb), fetchTexel(tex, xs.y, ys.x, srgb), tx),
                lerp(fetchTexel(tex, xs.x, ys.y, srgb), fetchTexel(tex, xs.y, ys.y, srgb), tx), ty);
}
vec4 fetchTangent(uint i) { return texelFetch(uTangents, int(i)); }
vec2 fetchUv(uint i) { return texelFetch(uUvs, int(i)).xy; }

// SurfaceKernels.h hash32, cameraCoverageKey and coverageRandom, bit for bit:
// stochastic transparency decides as GBufferRT and PathTracer's camera rays do.
uint hash32(uint x) {
    x ^= x >> 16;
    x *= 0x7FEB352Du;
    x ^= x >> 15;
    x *= 0x846CA68Bu;
    x ^= x >> 16;
    return x;
}
uint cameraCoverageKey(uint x, uint y, uint frame) {
    return hash32(x + hash32(y + hash32(frame + 0x9E3779B9u)));
}
float coverageRandom(uint key, uint instance, uint prim) {
    return float(hash32(key + hash32(instance + hash32(prim))) >> 8) * (1.0 / 16777216.0);
}

// CameraKernels.h clipToUv: frame uv, origin top-left; false behind the camera.
bool clipToUv(vec4 clip, out vec2 uv) {
    uv = vec2(0.5 * clip.x / clip.w + 0.5, 0.5 - 0.5 * clip.y / clip.w);
    return clip.w > 1e-12;
}

// SurfaceKernels.h specularAlbedo: Karis' fit of the GGX + Schlick directional albedo.
vec3 specularAlbedo(vec3 f0, float NdotV, float roughness) {
    const vec4 c0 = vec4(-1.0, -0.0275, -0.572, 0.022);
    const vec4 c1 = vec4(1.0, 0.0425, 1.04, -0.04);
    vec4 r = roughness * c0 + c1;
    float a004 = min(r.x * r.x, exp2(-9.28 * NdotV)) * r.x + r.y;
    float a = -1.04 * a004 + r.z;
    float b = 1.04 * a004 + r.w;
    return clamp(f0 * a + b, 0.0, 1.0);
}

void main() {
    const uint instance = uDraw.x;
    const mat4 world = uWorld;
    const mat3 normalMatrix = uNormalMatrix;

    const uint prim = uint(gl_PrimitiveID);
    const uvec3 tri = texelFetch(uTriangles, int(prim)).xyz;
    const uint i0 = tri.x, i1 = tri.y, i2 = tri.z;
    const vec3 p0 = fetchPosition(i0), p1 = fetchPosition(i1), p2 = fetchPosition(i2);
    const vec3 e1 = p1 - p0, e2 = p2 - p0;
    const vec3 nObj = cross(e1, e2);

    // This pixel's image position: the clip control origin is upper left,
    // so gl_FragCoord is already in image pixels with row 0 at the top; the
    // jitter the rasterizer sampled with is added back.
    const vec2 pix = gl_FragCoord.xy + uFrame.jitter.zw;
    const float nx = 2.0 * pix.x / uFrame.viewport.x - 1.0;
    const float ny = 1.0 - 2.0 * pix.y / uFrame.viewport.y;

    // Ray-plane intersection in object space (barycentrics are affine
    // invariant). A ray grazing the plane (|cos| < 1e-4) makes it
    // ill-conditioned; there the interpolated object position is the better
    // estimate.
    const vec3 dObj = uObjRayBasis * vec3(1.0, nx, ny);
    const float denom = dot(dObj, nObj);
    vec3 q = vObjPos;
    if (denom * denom > 1e-8 * dot(dObj, dObj) * dot(nObj, nObj))
        q = uObjRayOrigin + dObj * (dot(p0 - uObjRayOrigin, nObj) / denom);

    // Barycentrics of q (GBufferKernels.h barycentrics).
    const vec3 rq = q - p0;
    const float d11 = dot(e1, e1), d12 = dot(e1, e2), d22 = dot(e2, e2);
    const float r1 = dot(rq, e1), r2 = dot(rq, e2);
    const float det = d11 * d22 - d12 * d12;
    float u = 0.0, v = 0.0;
    if (det != 0.0) {
        u = (d22 * r1 - d12 * r2) / det;
        v = (d11 * r2 - d12 * r1) / det;
    }
    // Covered pixels whose centre lies a rounding error outside the exact
    // triangle (the rasterizer snaps vertices to sub-pixel precision) are
    // clamped onto it, so vbuffer always names a point of the triangle, as a
    // ray tracer's would.
    u = max(u, 0.0);
    v = max(v, 0.0);
    if (u + v > 1.0) {
        const float s = u + v;
        u /= s;
        v /= s;
    }
    const float w = 1.0 - u - v;

    // SurfaceKernels.h evalSurface, term by term.
    const vec3 pObj = w * p0 + u * p1 + v * p2;
    const vec3 posW = (world * vec4(pObj, 1.0)).xyz;
    const vec3 prevPosW = (uPrevWorld * vec4(pObj, 1.0)).xyz;
    vec3 fn = normalize(normalMatrix * nObj);
    vec3 n = normalize(normalMatrix * (w * fetchNormal(i0) + u * fetchNormal(i1) + v * fetchNormal(i2)));
    const vec2 uv = w * fetchUv(i0) + u * fetchUv(i1) + v * fetchUv(i2);
    // dot(fn, dir) in world space has the sign of dot(nObj, dObj): the
    // normal matrix is the inverse transpose of the world matrix.
    const bool frontFacing = denom < 0.0;
    if (!frontFacing && uFlags.x != 0u) {
        fn = -fn;
        n = -n;
    }
    // Each textured slot is compiled in only where the drawn material has
    // it (TEXTURE_SLOT_<k>, a program variant): llvmpipe runs both sides of
    // a branch, masked, so an untextured draw would still pay for sampling.
#ifdef TEXTURE_SLOT_2
    if (uTextures.z >= 0) {
        const vec4 t4 = w * fetchTangent(i0) + u * fetchTangent(i1) + v * fetchTangent(i2);
        vec3 t = (world * vec4(t4.xyz, 0.0)).xyz;
        t = t - n * dot(n, t);
        const float tl = length(t);
        if (tl > 1e-8) {
            t /= tl;
            const vec3 b = cross(n, t) * (t4.w < 0.0 ? -1.0 : 1.0);
            vec3 m = sampleTexture(uNormalTex, 2, uv, false).xyz * 2.0 - 1.0;
            m.xy *= uEmissive.w;
            const vec3 mapped = t * m.x + b * m.y + n * m.z;
            if (dot(mapped, mapped) > 1e-12) n = normalize(mapped);
        }
    }
#endif
    vec4 base = uBaseColorFactor;
#ifdef TEXTURE_SLOT_0
    if (uTextures.x >= 0) base *= sampleTexture(uBaseColorTex, 0, uv, true);
#endif
    float metallic = uMaterialParams.x, roughness = uMaterialParams.y;
#ifdef TEXTURE_SLOT_1
    if (uTextures.y >= 0) {
        const vec4 mr = sampleTexture(uMetalRoughTex, 1, uv, false);
        roughness *= mr.g;
        metallic *= mr.b;
    }
#endif
    metallic = clamp(metallic, 0.0, 1.0);
    roughness = clamp(roughness, 0.0, 1.0);
    vec3 emission = uEmissive.xyz;
#ifdef TEXTURE_SLOT_3
    if (uTextures.w >= 0) emission *= sampleTexture(uEmissiveTex, 3, uv, true).rgb;
#endif

    // View depth along the camera axis, as the RT pass measures it.
    const float depth = dot(posW - uFrame.camOrigin.xyz, uFrame.camForward.xyz);

    // Screen-space derivatives, in uniform control flow and before any
    // discard (GLSL 4.50, section 8.14.1); the fine variants difference
    // within each pixel pair rather than once per 2x2 quad. They come from
    // the interpolated attributes, which are valid in helper invocations:
    // llvmpipe does not perform storage-buffer loads for helper lanes, so
    // the exact values above are garbage there. On the triangle's plane the
    // two agree to rounding. As in GBufferRT, the normal term uses the
    // interpolated vertex normal (before normal mapping); its sign flip for
    // double-sided back faces is constant over the quad and does not
    // change the magnitudes.
    const vec3 posI = vPosW;
    const float depthI = dot(posI - uFrame.camOrigin.xyz, uFrame.camForward.xyz);
    const vec3 nI = normalize(vNormalW);
    const float dzdx = dFdxFine(depthI), dzdy = dFdyFine(depthI);
    const vec3 dpdx = dFdxFine(posI), dpdy = dFdyFine(posI);
    const vec3 dndx = dFdxFine(nI), dndy = dFdyFine(nI);

#ifdef ALPHA_TEST
    // SurfaceKernels.h surfaceCovers. The pixel is gl_FragCoord's (row 0 at
    // the top, see the clip control), not the jittered sample position.
    if (uFlags.y != 0u && base.a < uMaterialParams.z) discard;
    if (uFlags.z != 0u) {
        const uint key = cameraCoverageKey(uint(gl_FragCoord.x), uint(gl_FragCoord.y), uFrame.counters.x);
        if (!(coverageRandom(key, instance, prim) < base.a)) discard;
    }
#endif

#ifdef OUT_POSW
    oPosW = vec4(posW, 1.0);
#endif
#ifdef OUT_NORMW
    oNormW = vec4(n, 0.0);
#endif
#ifdef OUT_FACENORMALW
    oFaceNormalW = vec4(fn, 0.0);
#endif
#ifdef OUT_LINEARZ
    oLinearZ = vec2(depth, max(abs(dzdx), abs(dzdy)));
#endif
#ifdef OUT_PNFWIDTH
    oPnFwidth = vec2(length(abs(dpdx) + abs(dpdy)), length(abs(dndx) + abs(dndy)));
#endif
#ifdef OUT_MVEC
    // CameraKernels.h surfaceMotion: both positions through unjittered matrices.
    vec2 uvCur, uvPrev;
    const bool curOk = clipToUv(uFrame.viewProj * vec4(posW, 1.0), uvCur);
    const bool prevOk = clipToUv(uFrame.prevViewProj * vec4(prevPosW, 1.0), uvPrev);
    oMvec = curOk && prevOk ? uvPrev - uvCur : vec2(0.0);
#endif
#ifdef OUT_ALBEDO
    oAlbedo = vec4(base.rgb * (1.0 - metallic), 1.0);
#endif
#ifdef OUT_SPECALBEDO
    // This pixel's camera ray in world space (CameraKernels.h cameraRayDir).
    const vec3 dir = uFrame.camForward.xyz + uFrame.camRight.xyz * (nx * uFrame.lens.x * uFrame.lens.y) +
                     uFrame.camUp.xyz * (ny * uFrame.lens.x);
    const float NdotV = clamp(-dot(n, normalize(dir)), 0.0, 1.0);
    oSpecAlbedo = vec4(specularAlbedo(mix(vec3(0.04), base.rgb, metallic), NdotV, roughness), 1.0);
#endif
#ifdef OUT_EMISSION
    oEmission = vec4(emission, 1.0);
#endif
#ifdef OUT_VBUFFER
    oVBuffer = uvec4(instance, prim, floatBitsToUint(u), floatBitsToUint(v));
#endif
#ifdef OUT_MESHID
    oMeshId = instance;
#endif
}
)glsl";

// Miss pixels: a full-screen triangle depth-tested GL_EQUAL against the
// cleared depth (0) shades exactly the pixels no triangle covered, writing
// every miss value. Together with the geometry this writes each pixel of
// each attachment once, which is cheaper on llvmpipe than clearing the
// colour attachments first (clears are full memory passes too).
constexpr char kMissVS[] = R"glsl(
void main() {
    const vec2 corner = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(corner, 0.0, 1.0);
}
)glsl";

constexpr char kMissFS[] = R"glsl(

bool clipToUv(vec4 clip, out vec2 uv) {
    uv = vec2(0.5 * clip.x / clip.w + 0.5, 0.5 - 0.5 * clip.y / clip.w);
    return clip.w > 1e-12;
}

// GBufferKernels.h missSample: zeros, linearZ (-1, 0), ids ~0u, and the
// motion of CameraKernels.h missMotion: the pixel's direction at infinity
// seen through the previous camera's rotation (translation does not move
// the sky).
void main() {
#ifdef OUT_POSW
    oPosW = vec4(0.0);
#endif
#ifdef OUT_NORMW
    oNormW = vec4(0.0);
#endif
#ifdef OUT_FACENORMALW
    oFaceNormalW = vec4(0.0);
#endif
#ifdef OUT_LINEARZ
    oLinearZ = vec2(-1.0, 0.0);
#endif
#ifdef OUT_PNFWIDTH
    oPnFwidth = vec2(0.0);
#endif
#ifdef OUT_MVEC
    const vec2 pix = gl_FragCoord.xy + uFrame.jitter.zw;
    const float nx = 2.0 * pix.x / uFrame.viewport.x - 1.0;
    const float ny = 1.0 - 2.0 * pix.y / uFrame.viewport.y;
    const vec3 dir = uFrame.camForward.xyz + uFrame.camRight.xyz * (nx * uFrame.lens.x * uFrame.lens.y) +
                     uFrame.camUp.xyz * (ny * uFrame.lens.x);
    vec2 uvCur, uvPrev;
    const bool curOk = clipToUv(uFrame.proj * (uFrame.view * vec4(dir, 0.0)), uvCur);
    const bool prevOk = clipToUv(uFrame.proj * (uFrame.prevView * vec4(dir, 0.0)), uvPrev);
    oMvec = curOk && prevOk ? uvPrev - uvCur : vec2(0.0);
#endif
#ifdef OUT_ALBEDO
    oAlbedo = vec4(0.0);
#endif
#ifdef OUT_SPECALBEDO
    oSpecAlbedo = vec4(0.0);
#endif
#ifdef OUT_EMISSION
    oEmission = vec4(0.0);
#endif
#ifdef OUT_VBUFFER
    oVBuffer = uvec4(0xFFFFFFFFu);
#endif
#ifdef OUT_MESHID
    oMeshId = 0xFFFFFFFFu;
#endif
}
)glsl";

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
        for (int slot = 0; slot < 4; ++slot)
            if (variant & (kVariantTextureSlot0 << slot))
                defines += "#define TEXTURE_SLOT_" + std::to_string(slot) + " 1\n";
        const bool miss = variant & kVariantMiss;
        // "#version" must come first: defines go right after the common block's version line.
        std::string common = kShaderCommon;
        const size_t afterVersion = common.find('\n', common.find("#version")) + 1;
        common.insert(afterVersion, defines);
        GLuint p = miss ? linkProgram(common + kMissVS, common + kFragmentOutputs + kMissFS)
                        : linkProgram(common + kGeometryVS, common + kFragmentOutputs + kGeometryFS);
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
    p.addEnum("cullMode", &mCullMode, CullMode::Back, {"none", "back"})
        .doc("cull back faces of single-sided materials (double-sided ones are always drawn)");
    p.add("alphaTest", &mAlphaTest, true)
        .doc(
            "alphaMode MASK discards fragments where alpha < alphaCutoff; BLEND is stochastic transparency (kept "
            "with probability alpha, decided as in GBufferRT); false: every material opaque");
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

    const bool cullBack = mCullMode == CullMode::Back;
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
            const bool alphaTested = mAlphaTest && (mat.flags.y != 0 || mat.flags.z != 0);

            uint32_t textured = 0;
            for (int slot = 0; slot < 4; ++slot)
                if (mat.textures[slot] >= 0) textured |= kVariantTextureSlot0 << slot;
            const GLuint program = g.program(groupMask | (alphaTested ? kVariantAlphaTest : 0u) | textured);
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

        // Miss values where no triangle was drawn (see kMissFS).
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
