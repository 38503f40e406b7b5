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
#ifdef STATIC_INSTANCE
    // The instance did not move (uPrevWorld == uWorld): last frame's position is this one.
    const vec3 prevPosW = posW;
#else
    const vec3 prevPosW = (uPrevWorld * vec4(pObj, 1.0)).xyz;
#endif
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
