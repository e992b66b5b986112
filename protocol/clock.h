// The clock both cluster roles time heartbeats, rates and timeouts with.
#pragma once

namespace perch {

// Seconds on the monotonic clock (steady: never jumps with the wall clock).
double MonotonicSeconds();

}  // namespace perch
