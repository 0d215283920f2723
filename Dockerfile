# dolfin_mpm on Debian 12's DOLFINx 0.5.2: the route `make setup` takes on a Debian machine.
#
#     docker build -t dolfin_mpm .          # also runs a short silo discharge as a check
#     docker run --rm -it -v "$PWD/results:/opt/dolfin_mpm/results" dolfin_mpm \
#         dolfin-mpm run demos/silo.toml --output results/silo
#
# Open MPI refuses to run as root without its two confirmations; they are set here, as the
# container's user is root.
FROM debian:12
RUN apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        make ca-certificates gcc libc6-dev && rm -rf /var/lib/apt/lists/*
WORKDIR /opt/dolfin_mpm
COPY . .
RUN make setup VENV=/opt/venv && rm -rf /var/lib/apt/lists/*
ENV PATH=/opt/venv/bin:$PATH \
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    DOLFIN_MPM_CACHE_DIR=/opt/dolfin_mpm/.kernels
RUN dolfin-mpm run demos/silo.toml --set time.end=0.02 --output /tmp/check -q && rm -rf /tmp/check
CMD ["dolfin-mpm", "--help"]
