#include "ImageSequenceDevice.h"

#include "loom/Launch.h"

namespace loom::sequence {

bool deviceRuns(DeviceKind device) {
    return device != DeviceKind::Cpu && launchesReach(device);
}

}  // namespace loom::sequence
