#include "loom/Reflection.h"

#include <algorithm>
#include <cmath>

namespace loom {

const char* fieldKindName(FieldKind k) {
    switch (k) {
        case FieldKind::Input: return "input";
        case FieldKind::Output: return "output";
        case FieldKind::Internal: return "internal";
        case FieldKind::History: return "history";
    }
    return "?";
}

const char* fieldRoleName(FieldRole r) {
    switch (r) {
        case FieldRole::None:
            return "";
        case FieldRole::DisplayInput:
            return "displayInput";
    }
    return "?";
}

void FieldDesc::resolveSize(uint32_t frameWidth, uint32_t frameHeight, uint32_t& w, uint32_t& h) const {
    switch (sizeMode) {
        case SizeMode::Frame: w = frameWidth; h = frameHeight; break;
        case SizeMode::Scale:
            w = std::max<uint32_t>(1, uint32_t(std::lround(frameWidth * double(scaleX))));
            h = std::max<uint32_t>(1, uint32_t(std::lround(frameHeight * double(scaleY))));
            break;
        case SizeMode::Fixed: w = fixedWidth; h = fixedHeight; break;
        case SizeMode::Blocks:
            w = std::max<uint32_t>(1, uint32_t((uint64_t(frameWidth) + blockWidth - 1) / blockWidth));
            h = std::max<uint32_t>(1, uint32_t((uint64_t(frameHeight) + blockHeight - 1) / blockHeight));
            break;
    }
}

FieldBuilder Reflection::add(std::string name, FieldKind kind, Format f) {
    FieldDesc d;
    d.name = std::move(name);
    d.kind = kind;
    d.format = f;
    mFields.push_back(std::move(d));
    return FieldBuilder(mFields.back());
}

const FieldDesc* Reflection::find(const std::string& name) const {
    for (const auto& f : mFields)
        if (f.name == name) return &f;
    return nullptr;
}

const FieldDesc* Reflection::findRole(FieldRole role) const {
    for (const auto& f : mFields)
        if (role != FieldRole::None && f.role == role) return &f;
    return nullptr;
}

std::vector<std::string> Reflection::names(FieldKind kind) const {
    std::vector<std::string> out;
    for (const auto& f : mFields)
        if (f.kind == kind) out.push_back(f.name);
    return out;
}

}  // namespace loom
