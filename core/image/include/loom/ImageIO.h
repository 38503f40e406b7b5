#pragma once
// Reading and writing images: EXR for float and uint formats (OpenEXR), PNG
// for 8-bit formats (stb). Writes are atomic (loom/Files.h), so a reader
// never sees a half-written image.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "loom/Texture.h"

namespace loom {

/// The file extension a texture of this format is dumped as: "exr" for float
/// and uint formats, "png" for 8-bit formats.
const char* imageExtension(Format f);

/// Writes a texture. EXR: R32F/RG32F/RGBA32F as FLOAT channels, RGBA16F as
/// HALF, R32U/RG32U/RGBA32U as UINT; channels named R, G, B, A. PNG:
/// RGBA8Unorm and RGBA8Srgb as 4-channel 8-bit. Throws loom::Error (Runtime
/// kind for I/O failures, naming the path; BadInput when the folder does not
/// exist or is not writable). `attributes`: string attributes of an EXR's
/// header (name -> value), which ExrFile::stringAttribute reads back; a PNG
/// carries none.
void writeImage(const std::filesystem::path& path, const Texture& tex,
                const std::map<std::string, std::string>& attributes = {});

/// Reads an EXR (into RGBA32F, or RGBA32U when all channels are UINT; missing
/// channels are 0, alpha 1), a Radiance RGBE .hdr (RGBA32F, alpha 1) or a PNG
/// (RGBA8Unorm), told apart by their first bytes. Throws loom::Error
/// (BadInput) for a missing, malformed or truncated file.
Texture readImage(const std::filesystem::path& path);

/// Reads a Radiance RGBE .hdr (flat or run-length encoded rows, "-Y h +X w")
/// into RGBA32F, alpha 1. Throws loom::Error (BadInput) for a missing file,
/// another format, or a damaged or truncated one.
Texture readRadianceHdr(const std::filesystem::path& path);

/// Why stb could not decode an image held in memory, for an error message: "an empty file", "a truncated or
/// corrupt JPEG (stb: bad huffman code)", "a truncated or corrupt PNG (...)", or, when the leading bytes are
/// neither, "not a PNG or JPEG image (it starts with bytes 47 49 46 38)". `reason`: stbi_failure_reason().
std::string describeImageDecodeFailure(const unsigned char* bytes, size_t size, const char* reason);

}  // namespace loom
