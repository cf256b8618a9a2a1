# NATS for gmr-server replicas (docs/deployment.md), from Debian's package:
#   docker build -f docker/nats.Dockerfile -t gmr-nats docker
FROM debian:12-slim
RUN apt-get update -qq && apt-get install -y -qq --no-install-recommends nats-server \
 && rm -rf /var/lib/apt/lists/*
USER nobody
EXPOSE 4222
# deploy/k8s gives it a configuration with authorization (-c /etc/nats/nats.conf);
# without arguments it listens on every address, unauthenticated.
ENTRYPOINT ["nats-server"]
CMD ["-a", "0.0.0.0", "-p", "4222"]
