#pragma once
// Named channels of EXR files as renderers write them, and numbered sequences of such files. A single-layer image
// has channels R, G, B, A; a multilayer one names each channel "<layer>.<component>", where the layer may itself
// hold dots (Blender: "ViewLayer.Noisy Image.R", "ViewLayer.Vector.X", "ViewLayer.Depth.Z"). ExrFile opens a file,
// says what it holds and reads any set of its channels in one pass over the pixels.
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "loom/Texture.h"

namespace loom {

/// The file of frame `frame` of a numbered sequence. `pattern` holds one frame field: printf's "%d", "%Nd" (padded
/// with spaces) or "%0Nd" (with zeros), N up to 18, with "%%" for a literal '%'; or, without a printf field, the
/// last run of N '#' (N digits, zero-padded, as Blender names its output; every other '#' is literal). Throws
/// loom::Error (BadInput, at `where`) when the pattern holds no field, two printf fields, or a '%' it cannot read,
/// or when the frame is negative.
std::string sequenceFramePath(std::string_view pattern, int64_t frame, const std::string& where);

/// "" when `path` names an existing file; else why it cannot be opened, to follow the path in a message: "does not
/// exist", "is a symbolic link loop", "is a symbolic link to a missing file", "is not a regular file".
std::string fileAbsence(const std::filesystem::path& path);

/// A source of one image per frame: a numbered file pattern and, for a multilayer EXR, the layer to read.
struct SequenceSource {
    std::string pattern;  ///< see sequenceFramePath
    std::string layer;    ///< empty: the file's R, G, B, A (or Y)
};

/// Splits "PATTERN[:LAYER]" (for instance "frames/noisy_####.exr:ViewLayer.Noisy Image") at the colon that
/// follows ".exr". Without one, the whole text is the pattern.
SequenceSource parseSequenceSource(std::string_view spec);

enum class ExrSampleType : uint8_t { Uint, Half, Float };

/// "UINT", "HALF" or "FLOAT".
const char* exrSampleTypeName(ExrSampleType t);

struct ExrChannel {
    std::string name;
    ExrSampleType type;
};

/// One channel read into memory: `base` is pixel (0, 0)'s value, 4 bytes (a float, or a uint32 when `asUint`);
/// OpenEXR converts HALF and FLOAT to float. An empty `channel` (or one the file lacks) is filled with `fill`.
struct ExrChannelRead {
    std::string channel;
    std::byte* base = nullptr;
    size_t xStride = 0;  ///< bytes between horizontal neighbours
    size_t yStride = 0;  ///< bytes between rows
    bool asUint = false;
    double fill = 0.0;
};

/// An open EXR file: its header on construction, its pixels on read(). Single-part scanline or tiled files (the
/// first part of a multi-part file). Every failure is a loom::Error (BadInput) naming the file.
class ExrFile {
public:
    explicit ExrFile(const std::filesystem::path& path);
    ~ExrFile();
    ExrFile(ExrFile&&) noexcept;
    ExrFile& operator=(ExrFile&&) noexcept;

    const std::filesystem::path& path() const;
    uint32_t width() const;
    uint32_t height() const;
    /// Every channel, sorted by name as the file stores them.
    const std::vector<ExrChannel>& channels() const;
    const ExrChannel* findChannel(std::string_view name) const;
    /// OpenEXR's standard attribute worldToCamera, row-major, for row vectors (p_camera = p_world * M), if the
    /// file has it.
    std::optional<std::array<float, 16>> worldToCamera() const;
    /// A string attribute of the header (writeImage's `attributes`), if the file has one of that name and type.
    std::optional<std::string> stringAttribute(const std::string& name) const;

    /// The channels of `layer` by component: R, G, B, A, else X, Y, Z, W, else U, V under "<layer>." (the bare
    /// names for an empty layer), each at its component's place, "" where the file lacks it, trailing gaps
    /// dropped. A named layer with one channel gives just that one ("ViewLayer.Depth" gives "ViewLayer.Depth.Z"),
    /// and so does a layer that names a channel; an empty layer with none of these gives "Y" (luminance) if the
    /// file has it. Empty when the file has no such layer.
    std::vector<std::string> layerChannels(std::string_view layer) const;
    /// The layers the file holds (each channel's name up to its last dot; "" for bare names), sorted.
    std::vector<std::string> layers() const;
    /// How many parts the file has (1 for a single-part file; ExrFile reads the first).
    int partCount() const;
    /// The part (from 0) of a multi-part file whose channels hold `layer`, -1 if none does; for a message that says
    /// where a layer ExrFile does not read is.
    int partWithLayer(std::string_view layer) const;

    /// Reads the pixels of the given channels in one pass. Each destination holds width() x height() values.
    void read(const std::vector<ExrChannelRead>& reads);
    /// Reads `layer` (layerChannels) into RGBA32F: up to four components in order, the rest 0 (alpha 1); a bare
    /// Y channel (luminance) fills R, G and B. Throws BadInput, listing the layers
    /// the file has, when it has no such layer or the layer's channels are UINT.
    Texture readRgba(std::string_view layer);

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

}  // namespace loom
