-- wrk script: GETs of chunk keys drawn uniformly at random from server_bench.py's store
-- (GRID z, y, x under PREFIX/0/c/0/), each thread seeded apart; with IF_NONE_MATCH set, one
-- key revalidated with that ETag instead (the 304 load).
--
--   wrk -s benchmarks/wrk_random_keys.lua http://HOST:PORT -- PREFIX NZ NY NX [ETAG]
local prefix, nz, ny, nx, etag
local counter = 0

function setup(thread)
  counter = counter + 1
  thread:set("seed", counter * 7919)
end

function init(args)
  prefix = args[1] or "/bench"
  nz, ny, nx = tonumber(args[2] or 20), tonumber(args[3] or 25), tonumber(args[4] or 40)
  etag = args[5]
  math.randomseed(seed or 1)
  if etag then
    wrk.headers["If-None-Match"] = etag
  end
end

function request()
  if etag then
    return wrk.format("GET", prefix .. "/0/c/0/0/0/0")
  end
  local path = string.format("%s/0/c/0/%d/%d/%d", prefix,
    math.random(0, nz - 1), math.random(0, ny - 1), math.random(0, nx - 1))
  return wrk.format("GET", path)
end

function done(summary, latency, requests)
  io.write(string.format("RESULT requests=%d duration_us=%d bytes=%d p50_us=%d p99_us=%d errors=%d\n",
    summary.requests, summary.duration, summary.bytes,
    latency:percentile(50), latency:percentile(99),
    summary.errors.connect + summary.errors.read + summary.errors.write +
    summary.errors.status + summary.errors.timeout))
end
