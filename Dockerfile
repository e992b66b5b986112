# Perch image for the cluster (k8s/). Debian 12, built from this source tree.
#   docker build -t perch:latest .
FROM debian:12 AS build
WORKDIR /src
COPY scripts/install-deps.sh scripts/install-deps.sh
RUN bash scripts/install-deps.sh && rm -rf /var/lib/apt/lists/*
COPY . .
# Instruction set of the image (CMake PERCH_MARCH): x86-64-v3 (AVX2, FMA) runs on server CPUs since
# 2013; --build-arg PERCH_MARCH=x86-64-v2 for older nodes.
ARG PERCH_MARCH=x86-64-v3
RUN cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DPERCH_MARCH="$PERCH_MARCH" \
    && cmake --build build -j"$(nproc)" --target perch \
    && cmake --install build --prefix /opt/perch-install

FROM debian:12
RUN apt-get update -qq && apt-get install -y -qq --no-install-recommends \
      libbullet3.24 libbullet-extras3.24 libtinyobjloader2rc10 libzmq5 libprotobuf32 libspdlog1.10 libfmt9 libpng16-16 libssl3 zlib1g libcpp-httplib0.11 \
      libprometheus-cpp-pull1.0 libprometheus-cpp-core1.0 libcivetweb1 \
    && rm -rf /var/lib/apt/lists/*
# The install tree: /usr/local/bin/perch finds its data in /usr/local/share/perch by itself
# (common/paths.h), the same layout `cmake --install` and the .deb give.
COPY --from=build /opt/perch-install /usr/local
WORKDIR /usr/local/share/perch
ENTRYPOINT []
CMD ["perch", "--help"]
