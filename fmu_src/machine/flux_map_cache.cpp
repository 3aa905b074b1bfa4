// The shared flux maps; see flux_map_cache.hpp.
#include "machine/flux_map_cache.hpp"

#include <cstdint>
#include <deque>
#include <mutex>

#include "machine/map_file.hpp"

namespace ipmsm {
namespace {

// Enough for the maps of one co-simulation (controller and plant share one), bounded because
// every entry holds a spline of up to 64 MiB.
constexpr std::size_t kCachedMaps = 4;

struct Entry {
    std::uint64_t hash;
    std::size_t size;
    std::string name;  // the path the map was parsed from: its messages name it
    std::shared_ptr<const FluxMap> map;
};

std::mutex cache_mutex;
std::deque<Entry> cache;  // most recently used first

}  // namespace

std::shared_ptr<const FluxMap> shared_flux_map(const std::string& path) {
    std::string text;
    try {
        text = read_map_file(path);
    } catch (const MapFileError& e) {
        throw FluxMapError("flux map '" + quoted_excerpt(path) + "': " + e.what());
    }
    return shared_flux_map_text(text, path);
}

std::shared_ptr<const FluxMap> shared_flux_map_text(const std::string& text, const std::string& path) {
    const std::uint64_t hash = content_hash(text);
    {
        std::lock_guard<std::mutex> lock(cache_mutex);
        for (auto it = cache.begin(); it != cache.end(); ++it)
            if (it->hash == hash && it->size == text.size() && it->name == path) {
                Entry e = *it;
                cache.erase(it);
                cache.push_front(e);
                return e.map;
            }
    }
    auto map = std::make_shared<const FluxMap>(parse_flux_map_text(text, path));  // outside the lock
    std::lock_guard<std::mutex> lock(cache_mutex);
    cache.push_front(Entry{hash, text.size(), path, map});
    if (cache.size() > kCachedMaps) cache.pop_back();
    return map;
}

}  // namespace ipmsm
