# bouncewear: the HTTP service with its SQLite database on a volume.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
# Every kernel, whatever CPU builds the image: the image runs AVX-512 where its host has it.
RUN BOUNCEWEAR_ALL_KERNELS=1 cargo build --release --locked --bin bouncewear

FROM debian:bookworm-slim
RUN useradd --system --home /data bouncewear && mkdir -p /data && chown bouncewear /data
COPY --from=build /src/target/release/bouncewear /usr/local/bin/bouncewear
USER bouncewear
VOLUME /data
EXPOSE 8080
ENV BOUNCEWEAR_BIND=0.0.0.0:8080 \
    BOUNCEWEAR_DATABASE=sqlite:///data/bouncewear.db
# The image has no curl: the binary asks its own /healthz (BOUNCEWEAR_HEALTH_URL when the port moves).
HEALTHCHECK --interval=30s --timeout=3s --start-period=10s --retries=3 CMD ["bouncewear", "health"]
ENTRYPOINT ["bouncewear", "serve"]
