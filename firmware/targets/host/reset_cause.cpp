// The host build's reset cause (hal/reset_cause.hpp): the process always starts afresh, as
// from power-on.
#include "../../hal/reset_cause.hpp"

namespace hq {

ResetCause reset_cause() { return ResetCause::PowerOn; }

}  // namespace hq
