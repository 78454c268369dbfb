// Order statistics of the large per-Gaussian arrays the first view reads (issue 37: on the 7 M
// city the serial nth_element and sort of dense_content took most of a 17 s "loaded in"), on
// several threads, with exactly the values std::nth_element and std::sort give.
#pragma once

#include <cstddef>
#include <vector>

namespace catgs::server {

// The value std::nth_element would put at index k of a copy of `v` (the k-th smallest, from 0):
// a parallel histogram of the values' top 16 bits (sign, exponent, 7 mantissa bits; ordered as
// the floats are) finds the bucket holding rank k, then nth_element runs on that bucket alone.
// `v` must hold finite values (a validated model's). Throws std::invalid_argument when k >=
// v.size().
float kth_smallest(const std::vector<float>& v, std::size_t k);

// Sorts `v` ascending (the same array std::sort gives: values are totally ordered here, finite and
// never -0 next to +0 in a way that matters, as distances): blocks sorted on several threads,
// then merged pairwise, each round's merges in parallel.
void parallel_sort(std::vector<float>& v);

}  // namespace catgs::server
