#pragma once
// The camera: pose, projection, sub-pixel jitter, and last frame's values for
// motion vectors.
//
// Conventions (every pass follows them):
// - World space is right-handed, +Y up (glTF). The camera looks down its
//   local -Z axis; `view` is the inverse of its world transform.
// - Images have row 0 at the top. Pixel (x, y) covers [x, x+1) x [y, y+1);
//   its sample position is (x + 0.5 + jitter.x, y + 0.5 + jitter.y).
// - NDC: x right, y up, in [-1, 1]; an image position (px, py) maps to
//   ndc = (2 px / W - 1, 1 - 2 py / H). `proj` is OpenGL-style (z in [-1, 1])
//   and never contains jitter; rasterizers add it (see jitterNdcOffset).
// - uv over the frame: uv = (px / W, py / H), origin top-left.
//   Motion vector mvec = uvPrev - uvCur, both unjittered.
#include <cstdint>
#include <string>

#include <glm/glm.hpp>

namespace loom {

enum class JitterPattern : uint8_t { None, Halton, Stratified };

struct Camera {
    std::string name = "default";
    glm::mat4 world{1.f};  ///< camera to world (rigid)
    float fovY = 0.8f;     ///< vertical field of view, radians
    float aspect = 1.f;    ///< width / height (set by the renderer from the frame size)
    float nearZ = 0.05f, farZ = 1000.f;

    // Jitter, in pixels, in [-0.5, 0.5]^2; zero for JitterPattern::None.
    JitterPattern jitterPattern = JitterPattern::None;
    uint32_t jitterSampleCount = 16;  ///< period of the pattern
    glm::vec2 jitter{0.f};

    // Last frame's state (equal to the current one on the first frame and after a cut).
    glm::mat4 prevWorld{1.f};
    glm::vec2 prevJitter{0.f};

    glm::vec3 position() const { return glm::vec3(world[3]); }
    glm::vec3 forward() const { return -glm::normalize(glm::vec3(world[2])); }
    glm::vec3 up() const { return glm::normalize(glm::vec3(world[1])); }
    glm::vec3 right() const { return glm::normalize(glm::vec3(world[0])); }
    glm::mat4 view() const { return glm::inverse(world); }
    glm::mat4 prevView() const { return glm::inverse(prevWorld); }
    glm::mat4 proj() const;  ///< unjittered
    glm::mat4 viewProj() const { return proj() * view(); }
    glm::mat4 prevViewProj() const { return proj() * prevView(); }

    /// Offset to add to clip-space xy / w (NDC) so a rasterizer samples at the
    /// jittered positions: (-2 jitter.x / W, +2 jitter.y / H).
    glm::vec2 jitterNdcOffset(uint32_t width, uint32_t height) const;

    /// Sets this frame's jitter from the pattern (prevJitter keeps the last
    /// one). The pose and prevWorld are set by Scene::update.
    void beginFrame(uint64_t frameIndex);
    /// Forget the previous frame (camera cut): prev = current.
    void cut();

    /// Jitter (in pixels, [-0.5, 0.5]^2) of sample i of a pattern.
    static glm::vec2 jitterSample(JitterPattern pattern, uint32_t count, uint64_t i);
};

/// Radical inverse in base b of i (Halton sequence element).
float halton(uint64_t i, uint32_t base);

}  // namespace loom
