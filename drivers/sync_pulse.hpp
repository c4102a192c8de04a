// A sync-out pulse as a device personality's own setting asks for it (e.g.
// the VectorNav's Synchronization Control register 32: SyncOutMode, skip
// factor, polarity, pulse width), for the sample just encoded. The GPIO sync
// output (drivers/gpio_sync.hpp) drives its sync line by this instead of the
// scene's every_n_samples / pulse width / polarity while the device asks for
// any pulses; the 1PPS line is unaffected.
#pragma once

#include "core/types.hpp"

namespace imuemu::drivers {

struct DeviceSyncPulse {
  bool pulse = false;      // a leading edge at this sample
  TimeNs width_ns = 0;     // its width
  bool active_low = false; // negative pulse: the line idles high and pulses low
};

}  // namespace imuemu::drivers
