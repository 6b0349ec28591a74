// float kernels, one head per block (single-head layers: L queries per block); see rana_cpu_kernels.h.
#include "rana_cpu_kernels.h"

namespace rana_cpu {
RANA_CPU_KERNELS(, float, rana::f32v, 1)
}  // namespace rana_cpu
