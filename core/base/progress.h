// progress.h — internal to the library: a long call's count of work done, reported as a
// fraction through the progress callback its options carry (TruthOptions::progress,
// DefocusOptions::progress, BlurOptions::progress).
//
// Counted by units the call already loops over (rows of rays, layers, row chunks), never
// per pixel: with no callback an add() is one test of a pointer, with one it is a lock and
// an addition per unit, which the units' work dwarfs. The callback is called from one
// thread at a time, with rising fractions, whichever thread finishes a unit; throttling
// its output is the caller's (bokehtool prints at most a line a second).
#pragma once

#include <algorithm>
#include <functional>
#include <mutex>

namespace bokeh::detail {

class ProgressCounter {
public:
    /// `report` may be empty (nothing is counted); `total` units take the fraction from
    /// `from` to `to` (a phase of a longer call).
    ProgressCounter(const std::function<void(float)>& report, double total, float from = 0.0f, float to = 1.0f)
        : m_report(report ? &report : nullptr), m_total(total > 0.0 ? total : 1.0), m_from(from), m_to(to)
    {
    }
    ProgressCounter(const ProgressCounter&)            = delete;
    ProgressCounter& operator=(const ProgressCounter&) = delete;

    bool active() const { return m_report != nullptr; }

    /// `units` more done (any thread).
    void add(double units = 1.0)
    {
        if (!m_report)
            return;
        std::lock_guard<std::mutex> lock(m_lock);
        m_done += units;
        const float f = m_from + (m_to - m_from) * float(std::min(1.0, m_done / m_total));
        if (f > m_reported) {
            m_reported = f;
            (*m_report)(f);
        }
    }

private:
    const std::function<void(float)>* m_report;
    double m_total;
    float m_from, m_to;
    double m_done = 0.0;
    float m_reported = 0.0f;
    std::mutex m_lock;
};

}  // namespace bokeh::detail
