// float kernels, two heads per block (models with H = 2, e.g. the reconstruction kernels); see rana_cpu_kernels.h.
#include "rana_cpu_kernels.h"

namespace rana_cpu {
RANA_CPU_KERNELS(, float, rana::f32v, 2)
}  // namespace rana_cpu
