#pragma once
// What a pass declares about its fields: inputs, outputs, transient scratch
// and history, with formats and sizes.
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "loom/Format.h"

namespace loom {

enum class FieldKind : uint8_t {
    Input,     ///< read; produced by another pass
    Output,    ///< written; may be consumed by other passes or marked as a graph output
    Internal,  ///< transient scratch, valid only during the pass's execute
    History,   ///< persistent across frames, ping-ponged by the graph (prev / cur), or one texture when inPlace
};

const char* fieldKindName(FieldKind k);

enum class SizeMode : uint8_t {
    Frame,  ///< the frame size (default)
    Scale,  ///< the frame size times (scaleX, scaleY), rounded, at least 1
    Fixed,  ///< (fixedWidth, fixedHeight)
    Blocks, ///< one texel per blockWidth x blockHeight block of the frame: the frame size divided, rounded up
};

/// A standard meaning a field can declare, so a tool that drives graphs it does not know (`loom bench`) asks for
/// "the field that plays this role" instead of a pass type and a field name. A pass gives a role to at most one of its
/// fields, of the kind and format the role names (the planner refuses a pass that does otherwise).
enum class FieldRole : uint8_t {
    None,
    DisplayInput,  ///< input, RGBA32F: the linear, scene-referred image a display transform (tone mapping) maps
};

/// "displayInput" ("" for None).
const char* fieldRoleName(FieldRole r);

struct FieldDesc {
    std::string name;
    FieldKind kind = FieldKind::Input;
    Format format = Format::RGBA32F;
    bool optional = false;
    SizeMode sizeMode = SizeMode::Frame;
    float scaleX = 1.f, scaleY = 1.f;
    uint32_t fixedWidth = 0, fixedHeight = 0;
    uint32_t blockWidth = 1, blockHeight = 1;
    std::string doc;
    FieldRole role = FieldRole::None;  ///< the standard meaning it declares, if any
    /// History only: the pass updates each texel in place from that texel's last value (it reads prev(x, y) before
    /// it writes cur(x, y) and reads no other texel of the field), so one texture serves as both sides.
    bool inPlace = false;

    /// Resolved size for a frame of frameWidth x frameHeight.
    void resolveSize(uint32_t frameWidth, uint32_t frameHeight, uint32_t& w, uint32_t& h) const;
    bool operator==(const FieldDesc&) const = default;
};

/// Chained setters on the most recently declared field.
class FieldBuilder {
public:
    explicit FieldBuilder(FieldDesc& f) : mField(f) {}
    FieldBuilder& optional(bool v = true) { mField.optional = v; return *this; }
    FieldBuilder& scaled(float sx, float sy) {
        mField.sizeMode = SizeMode::Scale; mField.scaleX = sx; mField.scaleY = sy; return *this;
    }
    /// One texel per bw x bh block of the frame (a block's sample, a tile's bits): ceil(width / bw) x
    /// ceil(height / bh).
    FieldBuilder& perBlock(uint32_t bw, uint32_t bh) {
        mField.sizeMode = SizeMode::Blocks; mField.blockWidth = std::max(1u, bw); mField.blockHeight = std::max(1u, bh);
        return *this;
    }
    FieldBuilder& fixedSize(uint32_t w, uint32_t h) {
        mField.sizeMode = SizeMode::Fixed; mField.fixedWidth = w; mField.fixedHeight = h; return *this;
    }
    FieldBuilder& doc(std::string text) { mField.doc = std::move(text); return *this; }
    FieldBuilder& role(FieldRole r) {
        mField.role = r;
        return *this;
    }
    /// A history field updated texel by texel in place: one texture instead of a ping-pong pair (FieldDesc::inPlace).
    FieldBuilder& inPlace(bool v = true) {
        mField.inPlace = v;
        return *this;
    }

private:
    FieldDesc& mField;
};

/// The fields of one pass, in declaration order.
class Reflection {
public:
    FieldBuilder input(std::string name, Format f) { return add(std::move(name), FieldKind::Input, f); }
    FieldBuilder output(std::string name, Format f) { return add(std::move(name), FieldKind::Output, f); }
    FieldBuilder internal(std::string name, Format f) { return add(std::move(name), FieldKind::Internal, f); }
    FieldBuilder history(std::string name, Format f) { return add(std::move(name), FieldKind::History, f); }

    const std::vector<FieldDesc>& fields() const { return mFields; }
    const FieldDesc* find(const std::string& name) const;
    /// The field that plays `role`, or nullptr.
    const FieldDesc* findRole(FieldRole role) const;
    std::vector<std::string> names(FieldKind kind) const;

private:
    FieldBuilder add(std::string name, FieldKind kind, Format f);
    std::vector<FieldDesc> mFields;
};

}  // namespace loom
