// A small persistent thread pool that runs fn(i, worker) for i in [0, count).  Which thread
// runs which index does not matter: callers write per-index results and merge them in index
// order, so results are bitwise identical for any thread count.  `worker` (0 the caller,
// 1.. the helpers) lets a caller keep per-thread scratch memory, so chunks reuse buffers
// instead of allocating (and page-faulting) their own.
#pragma once
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace re {

class ThreadPool {
  public:
    static ThreadPool &instance() {
        static ThreadPool pool;
        return pool;
    }

    static int default_threads() {
        unsigned h = std::thread::hardware_concurrency();
        return h == 0 ? 1 : int(h);
    }

    using Job = std::function<void(size_t index, int worker)>;

    // Runs on `threads` threads in total, the caller included (threads above count are not
    // started).  Returns each worker's busy seconds (time inside fn), the caller's first.
    // Rethrows the first exception.
    std::vector<double> run(size_t count, int threads, const Job &fn) {
        if (threads < 1) threads = 1;
        if (size_t(threads) > count) threads = int(count > 0 ? count : 1);
        std::vector<double> busy(size_t(threads), 0.0);
        if (threads == 1) {  // the caller's thread alone: no pool, no lock, so callers run concurrently
            auto t0 = Clock::now();
            for (size_t i = 0; i < count; ++i) fn(i, 0);
            busy[0] = seconds_since(t0);
            return busy;
        }
        std::lock_guard<std::mutex> one_job_at_a_time(run_mutex_);
        grow(threads - 1);
        {
            std::lock_guard<std::mutex> lk(m_);
            job_ = &fn;
            busy_ = busy.data();
            count_ = count;
            next_.store(0);
            helpers_ = threads - 1;
            active_ = threads - 1;
            error_ = nullptr;
            ++generation_;
        }
        cv_.notify_all();
        work(0);
        std::unique_lock<std::mutex> lk(m_);
        done_cv_.wait(lk, [&] { return active_ == 0; });
        job_ = nullptr;
        busy_ = nullptr;
        if (error_) std::rethrow_exception(error_);
        return busy;
    }

    ~ThreadPool() {
        {
            std::lock_guard<std::mutex> lk(m_);
            stop_ = true;
        }
        cv_.notify_all();
        for (auto &t : workers_) t.join();
    }

  private:
    using Clock = std::chrono::steady_clock;
    static double seconds_since(Clock::time_point t0) {
        return std::chrono::duration<double>(Clock::now() - t0).count();
    }

    ThreadPool() = default;

    void grow(int n) {
        while (int(workers_.size()) < n) {
            int id = int(workers_.size());
            workers_.emplace_back([this, id] { loop(id); });
        }
    }

    // Worker `worker` takes indices until none is left; its busy time goes to busy_[worker]
    // (each worker writes its own entry).
    void work(int worker) {
        for (;;) {
            size_t i = next_.fetch_add(1);
            if (i >= count_) return;
            auto t0 = Clock::now();
            try {
                (*job_)(i, worker);
                busy_[worker] += seconds_since(t0);
            } catch (...) {
                std::lock_guard<std::mutex> lk(m_);
                if (!error_) error_ = std::current_exception();
                next_.store(count_);  // stop handing out work
            }
        }
    }

    void loop(int id) {
        size_t seen = 0;
        for (;;) {
            {
                std::unique_lock<std::mutex> lk(m_);
                cv_.wait(lk, [&] { return stop_ || generation_ != seen; });
                if (stop_) return;
                seen = generation_;
                if (id >= helpers_) continue;
            }
            work(id + 1);
            std::lock_guard<std::mutex> lk(m_);
            if (--active_ == 0) done_cv_.notify_all();
        }
    }

    std::mutex run_mutex_, m_;
    std::condition_variable cv_, done_cv_;
    std::vector<std::thread> workers_;
    const Job *job_ = nullptr;
    double *busy_ = nullptr;
    size_t count_ = 0, generation_ = 0;
    std::atomic<size_t> next_{0};
    int helpers_ = 0, active_ = 0;
    std::exception_ptr error_;
    bool stop_ = false;
};

// fn(c, a, b, worker) for the fixed chunks [a, b) = [c chunk, min(n, (c + 1) chunk)) of n
// items, on all hardware threads (none started for a single chunk).  For per-item work whose
// result depends on the item alone, or per-chunk results merged in chunk order: the same for
// any thread count.
template <class Fn>
void for_chunks(size_t n, size_t chunk, Fn &&fn) {
    const size_t chunks = (n + chunk - 1) / chunk;
    ThreadPool::instance().run(chunks, ThreadPool::default_threads(), [&](size_t c, int worker) {
        fn(c, c * chunk, std::min(n, (c + 1) * chunk), worker);
    });
}

}  // namespace re
