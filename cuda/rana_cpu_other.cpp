// double kernels (gradient checks) and one-lane blocks (the bodies as a GPU thread runs them, for tests);
// see rana_cpu_kernels.h.
#include "rana_cpu_kernels.h"

namespace rana_cpu {
RANA_CPU_KERNELS(, double, rana::f64v, 1)
RANA_CPU_KERNELS(, float, float, 1)
RANA_CPU_KERNELS(, double, double, 1)
}  // namespace rana_cpu
