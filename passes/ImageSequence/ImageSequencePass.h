#pragma once
// ImageSequence: frames another renderer (or an earlier Loom run) wrote as EXR files, read into the standard
// channels, so the graphs that denoise Loom's own frames take them unchanged (wiring by name).
//
// Each output channel has a source: a numbered file pattern and the layer of that file to read
// (loom/ExrFile.h). Presets give every source at once: `blender` reads one multilayer EXR per frame with the pass
// names of a Cycles View Layer, `loom` reads the files `loom render --dump` writes ("<Pass>.<field>.NNNN.exr").
// A channel parameter overrides its preset's source; "none" leaves the channel out.
//
// Conversions: normals from camera space (with the file's worldToCamera attribute), a one-channel depth into
// linearZ (miss -1, the derivative computed from neighbours), motion in pixels of either sign and y direction
// into uvPrev - uvCur, float object indices into mesh ids (SequenceConversions.h). Non-finite samples, in the file
// or made by a conversion, become 0 (depth: a miss) and are counted (stat nonFinite); albedos are clamped into
// [0, 4] and motion into +-1e4 frames (stat outOfRange); a worldToCamera that cannot turn normals (not finite,
// singular) stops the run with an error naming the file. A consumed channel the sequence lacks is filled: albedo 1
// (filtering without demodulation, with a warning), specAlbedo, emission, gradient and meshId 0; colour, normals,
// depth, motion and reference are required (an error names the channel and what the file holds).
//
// Frame k of the graph reads file number firstFrame + k. The files of the next frame are read on a background
// thread while the graph runs the current one, so the pass itself copies memory.
//
// On the emulated and cuda devices (docs/KERNELS.md) the frame is read and converted on the host all the same (a
// channel the sequence lacks is filled into a host staging texture the pass keeps), and each output is uploaded
// once a frame (copyTexture): the values are the CPU's bit for bit.
#include <array>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "SequenceConversions.h"
#include "loom/RenderPass.h"

namespace loom {

class ImageSequencePass final : public RenderPass {
public:
    enum class Preset : int { None, Loom, Blender };
    // Parameter values; Auto takes the preset's.
    enum class NormalSpace : int { Auto, World, Camera };
    enum class DepthKind : int { Auto, LinearZ, Depth };
    enum class Motion : int { Auto, Uv, PixelsFromPrevious, PixelsToPrevious };
    enum class MotionY : int { Auto, Down, Up };

    /// The output channels, in the order of kOutputs (ImageSequencePass.cpp).
    enum Output : int {
        Color,
        Albedo,
        SpecAlbedo,
        Emission,
        NormW,
        LinearZ,
        Mvec,
        MeshId,
        Gradient,
        Reference,
        kOutputCount
    };

    /// Everything a frame's reading depends on: the parameters with the preset applied (no Auto left).
    struct Settings {
        std::array<std::string, kOutputCount> source;  ///< "[PATTERN:]LAYER" alternatives split by '|', or ""
        std::array<bool, kOutputCount> optional{};     ///< the preset's source: absent is allowed
        std::string path;
        std::string layerPrefix;
        int firstFrame = 0;
        NormalSpace normals = NormalSpace::World;
        DepthKind depth = DepthKind::LinearZ;
        float missDepth = 1e9f;
        sequence::MotionKind motion = sequence::MotionKind::Uv;
        bool motionYUp = false;
        bool operator==(const Settings&) const = default;
    };
    struct Resolved;

    /// One frame as read and converted: a texture per channel the sequence has (empty otherwise).
    struct Frame {
        int64_t number = -1;
        std::array<Texture, kOutputCount> channels;
        uint64_t nonFinite = 0;          ///< samples that were not finite, read as 0
        uint64_t outOfRange = 0;         ///< finite values clamped into their channel's range (albedos, motion)
        bool cameraNormalsKept = false;  ///< camera-space normals without a worldToCamera to turn them
    };

    ImageSequencePass();
    ~ImageSequencePass() override;
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void compile(const CompileInfo& info) override;
    void execute(PassContext& ctx) override;
    bool runsOn(DeviceKind device) const override;
    /// The size of the first frame's file (firstFrame) of the first channel the sequence has, colour first: the
    /// frame size when none is given. Throws loom::Error (BadInput) where none of the sources' files exist.
    std::optional<glm::uvec2> naturalSize() const override;

    /// The sources of every channel: the preset's, then the channel parameters.
    Settings settings() const;
    /// Which alternative of each source the files hold, from frame `number`'s files. Throws loom::Error
    /// (BadInput) for a file or layer that a channel parameter names and that is not there.
    static Resolved resolve(const Settings& s, int64_t number);
    /// Reads frame `number` (no pass state: this runs on the reader thread). Throws loom::Error (BadInput) for a
    /// missing file or channel, a wrong size or sample type, a damaged file.
    static Frame readFrame(const Settings& s, const Resolved& r, int64_t number, uint32_t width, uint32_t height,
                           const std::array<bool, kOutputCount>& wanted);

private:
    Frame take(int64_t number, const Settings& s, const std::array<bool, kOutputCount>& wanted);
    void prefetch(int64_t number, const Settings& s, const std::array<bool, kOutputCount>& wanted);

    Preset mPreset = Preset::Blender;
    std::string mPath;
    std::string mLayer = "ViewLayer";
    std::array<std::string, kOutputCount> mSource;
    int mFirstFrame = 0;
    NormalSpace mNormals = NormalSpace::Auto;
    DepthKind mDepth = DepthKind::Auto;
    float mMissDepth = 1e9f;
    Motion mMotion = Motion::Auto;
    MotionY mMotionY = MotionY::Auto;

    uint32_t mWidth = 0, mHeight = 0;
    std::unique_ptr<Resolved> mResolved;
    Settings mResolvedFor;
    std::array<bool, kOutputCount> mConsumed{};  ///< read by a pass and not observed
    std::array<bool, kOutputCount> mFillWarned{};
    std::array<Texture, kOutputCount> mStaging;  ///< on a device: the host side of a filled output
    bool mLogged = false;
    bool mNonFiniteWarned = false;
    bool mOutOfRangeWarned = false;

    struct Pending {
        int64_t number = -1;
        Settings settings;
        std::array<bool, kOutputCount> wanted{};
        uint32_t width = 0, height = 0;
        std::future<Frame> frame;
    };
    std::unique_ptr<Pending> mPending;
};

}  // namespace loom
