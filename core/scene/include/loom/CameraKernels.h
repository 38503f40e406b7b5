#pragma once
// The camera as per-pixel kernels see it (plain data), with primary-ray
// generation and projection following the conventions in Camera.h.
#include <cmath>
#include <cstdint>

#include <glm/glm.hpp>

#include "loom/Camera.h"
#include "loom/Kernel.h"

namespace loom {

struct CameraData {
    glm::vec3 origin{0.f};
    glm::vec3 right{1.f, 0.f, 0.f}, up{0.f, 1.f, 0.f}, forward{0.f, 0.f, -1.f};
    float tanHalfFovY = 0.4f;
    float aspect = 1.f;
    glm::mat4 viewProj{1.f};      ///< unjittered
    glm::mat4 prevViewProj{1.f};  ///< unjittered, last frame
    glm::mat4 prevView{1.f};
    glm::mat4 view{1.f};
    glm::mat4 proj{1.f};
    glm::vec2 jitter{0.f};  ///< pixels
    uint32_t width = 1, height = 1;
};

/// Kernel view of a camera for a frame of width x height.
inline CameraData makeCameraData(const Camera& c, uint32_t width, uint32_t height) {
    CameraData d;
    d.origin = c.position();
    d.right = c.right();
    d.up = c.up();
    d.forward = c.forward();
    d.tanHalfFovY = std::tan(0.5f * c.fovY);
    d.aspect = c.aspect;
    d.view = c.view();
    d.proj = c.proj();
    d.viewProj = d.proj * d.view;
    d.prevView = c.prevView();
    d.prevViewProj = d.proj * d.prevView;
    d.jitter = c.jitter;
    d.width = width;
    d.height = height;
    return d;
}

/// Unnormalised direction through image position (px, py) (pixels, row 0 at top).
LOOM_HD inline glm::vec3 cameraRayDir(const CameraData& c, float px, float py) {
    const float nx = 2.f * px / float(c.width) - 1.f;
    const float ny = 1.f - 2.f * py / float(c.height);
    return c.forward + c.right * (nx * c.tanHalfFovY * c.aspect) + c.up * (ny * c.tanHalfFovY);
}

/// Direction of the jittered sample of pixel (x, y).
LOOM_HD inline glm::vec3 pixelRayDir(const CameraData& c, uint32_t x, uint32_t y) {
    return cameraRayDir(c, float(x) + 0.5f + c.jitter.x, float(y) + 0.5f + c.jitter.y);
}

/// Frame uv (origin top-left) of a homogeneous clip position; false when behind the camera.
LOOM_HD inline bool clipToUv(const glm::vec4& clip, glm::vec2& uv) {
    if (clip.w <= 1e-12f) return false;
    uv = glm::vec2(0.5f * clip.x / clip.w + 0.5f, 0.5f - 0.5f * clip.y / clip.w);
    return true;
}

/// Motion vector uvPrev - uvCur of a surface point (current and last frame's
/// world positions), both unjittered. Zero when either is behind the camera.
LOOM_HD inline glm::vec2 surfaceMotion(const CameraData& c, glm::vec3 posW, glm::vec3 prevPosW) {
    glm::vec2 cur, prev;
    if (!clipToUv(c.viewProj * glm::vec4(posW, 1.f), cur) || !clipToUv(c.prevViewProj * glm::vec4(prevPosW, 1.f), prev))
        return glm::vec2(0.f);
    return prev - cur;
}

/// Motion vector of a miss: the direction at infinity seen through the
/// previous camera's rotation (camera translation does not move the sky).
LOOM_HD inline glm::vec2 missMotion(const CameraData& c, glm::vec3 dir) {
    glm::vec2 cur, prev;
    if (!clipToUv(c.proj * (c.view * glm::vec4(dir, 0.f)), cur) ||
        !clipToUv(c.proj * (c.prevView * glm::vec4(dir, 0.f)), prev))
        return glm::vec2(0.f);
    return prev - cur;
}

}  // namespace loom
