// float kernels, four heads per block (models with H > 1); see rana_cpu_kernels.h.
#include "rana_cpu_kernels.h"

namespace rana_cpu {
RANA_CPU_KERNELS(, float, rana::f32v, 4)
}  // namespace rana_cpu
