#include "loom/RenderPass.h"

#include <algorithm>

#include "loom/Error.h"

namespace loom {

bool CompileInfo::isInputConnected(std::string_view name) const {
    return std::find(connectedInputs.begin(), connectedInputs.end(), name) != connectedInputs.end();
}
bool CompileInfo::isOutputConsumed(std::string_view name) const {
    return std::find(consumedOutputs.begin(), consumedOutputs.end(), name) != consumedOutputs.end();
}
bool CompileInfo::isOutputRead(std::string_view name) const {
    return std::find(readOutputs.begin(), readOutputs.end(), name) != readOutputs.end();
}
bool CompileInfo::isObserved(std::string_view name) const {
    return std::find(observedFields.begin(), observedFields.end(), name) != observedFields.end();
}

const BoundField* PassContext::find(std::string_view name, FieldKind kind) const {
    for (const auto& f : mFields)
        if (f.kind == kind && f.name == name) return &f;
    return nullptr;
}

namespace {
[[noreturn]] void undeclared(const std::string& pass, std::string_view name, FieldKind kind) {
    throw Error(Error::Info{ErrorKind::Runtime, {}, pass + "." + std::string(name),
                            std::string("the pass asked for ") + fieldKindName(kind) + " '" + std::string(name) +
                                "' which it did not declare in reflect()",
                            {}, "declare the field in reflect() or fix its name"});
}
}  // namespace

const Texture* PassContext::input(std::string_view name) const {
    const BoundField* f = find(name, FieldKind::Input);
    if (!f) undeclared(mPassName, name, FieldKind::Input);
    return f->cur;
}
Texture* PassContext::output(std::string_view name) const {
    const BoundField* f = find(name, FieldKind::Output);
    if (!f) undeclared(mPassName, name, FieldKind::Output);
    return f->cur;
}
Texture* PassContext::internal(std::string_view name) const {
    const BoundField* f = find(name, FieldKind::Internal);
    if (!f) undeclared(mPassName, name, FieldKind::Internal);
    return f->cur;
}
const Texture& PassContext::historyPrev(std::string_view name) const {
    const BoundField* f = find(name, FieldKind::History);
    if (!f) undeclared(mPassName, name, FieldKind::History);
    return *f->prev;
}
Texture& PassContext::historyCur(std::string_view name) const {
    const BoundField* f = find(name, FieldKind::History);
    if (!f) undeclared(mPassName, name, FieldKind::History);
    return *f->cur;
}

}  // namespace loom
