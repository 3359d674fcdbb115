# forklift-fleet: the `fleet` CLI in a venv, run as a non-root user.
#
#   docker build -t forklift-fleet .                 anywhere: python:3.11-slim, wheels from PyPI,
#                                                    torch's CPU build from download.pytorch.org
#   deploy/build-images                              with no image registry: a debootstrapped
#                                                    base and the local wheelhouse, offline
#   docker run --rm -v "$PWD/runs:/data/runs" --user "$(id -u):$(id -g)" \
#       forklift-fleet run --inprocess --layout small        (the image's user is fleet, uid 1000)
#
# Works with the classic builder and with BuildKit (no syntax directive: that would pull an
# image). When deploy/wheelhouse/ is in the context (deploy/build-images makes it), every
# package comes from there with --no-index; without it, from PyPI.
ARG BASE=python:3.11-slim

# --- the runtime dependencies, in their own stage so that a change of source keeps them ------
FROM ${BASE} AS deps
LABEL org.forklift-fleet.stage=deps
ENV PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_CACHE_DIR=1 PIP_ROOT_USER_ACTION=ignore
# PyTorch's CPU-only index: PyPI's torch for Linux is a CUDA build with GBs of nvidia packages
ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu
RUN python3 -m venv /opt/fleet
# pyproject.toml always; deploy/wheelhouse/deps/* only where it exists (the glob may match
# nothing, the COPY still has a source)
COPY pyproject.toml deploy/wheelhouse/dep[s] /tmp/deps/
# [project].dependencies alone (no test extras); then drop torch's C++ test programs (about
# 120 MB), which running it does not need
RUN set -eu; \
    /opt/fleet/bin/python -c 'import tomllib; \
[print(d) for d in tomllib.load(open("/tmp/deps/pyproject.toml", "rb"))["project"]["dependencies"]]' \
        > /tmp/requirements.txt; \
    grep -Ei '^torch([^a-z0-9_.-]|$)' /tmp/requirements.txt > /tmp/torch.txt || true; \
    if ls /tmp/deps/*.whl >/dev/null 2>&1; then \
        echo "installing the runtime dependencies from the wheelhouse"; \
        /opt/fleet/bin/pip install --no-index --find-links /tmp/deps -r /tmp/requirements.txt; \
    else \
        echo "installing the runtime dependencies from PyPI, torch from $TORCH_INDEX_URL"; \
        if [ -s /tmp/torch.txt ]; then \
            /opt/fleet/bin/pip install --index-url "$TORCH_INDEX_URL" -r /tmp/torch.txt; \
        fi; \
        /opt/fleet/bin/pip install -r /tmp/requirements.txt; \
    fi; \
    if /opt/fleet/bin/pip list 2>/dev/null | grep -Ei '^(nvidia-|triton )'; then \
        echo "CUDA packages were installed: torch is not the CPU build" >&2; exit 1; \
    fi; \
    rm -rf /tmp/deps /tmp/requirements.txt /tmp/torch.txt; \
    for t in /opt/fleet/lib/python3*/site-packages/torch; do \
        [ -d "$t" ] || continue; \
        rm -rf "$t/test" "$t"/bin/test_* "$t"/bin/*StoreTest; \
    done

# --- the project's wheel: the wheelhouse's, or built from the source here -------------------
# (a stage of its own, from the base and not from deps: deploy/build-images removes its images
# after a build, as they hold the whole context, wheelhouse included)
FROM ${BASE} AS project
LABEL org.forklift-fleet.stage=project
COPY . /src
RUN set -eu; mkdir /dist; \
    if ls /src/deploy/wheelhouse/project/*.whl >/dev/null 2>&1; then \
        cp /src/deploy/wheelhouse/project/*.whl /dist/; \
    else \
        python3 -m venv /tmp/build; \
        SOURCE_DATE_EPOCH=315532800 /tmp/build/bin/pip wheel --disable-pip-version-check \
            --no-cache-dir --no-deps -w /dist /src; \
    fi

# --- the image ---------------------------------------------------------------------------------
# mosquitto, the broker of a VDA 5050 session, comes with deploy/build-images' base and is
# installed here on any other.
# User fleet (uid 1000) owns /data and the mount points of compose.yaml's named volumes: a new
# named volume takes the owner of its mount point in the image, and root's where the image has
# none, which the user could not write to.
FROM ${BASE}
LABEL org.forklift-fleet.stage=image
ARG UID=1000
RUN set -eu; \
    if command -v useradd >/dev/null; then \
        useradd --uid "$UID" --user-group --create-home --home-dir /home/fleet \
            --shell /bin/sh fleet; \
    else \
        echo "fleet:x:$UID:$UID:forklift-fleet:/home/fleet:/bin/sh" >> /etc/passwd; \
        echo "fleet:x:$UID:" >> /etc/group; \
        mkdir -p /home/fleet; chown "$UID:$UID" /home/fleet; \
    fi; \
    mkdir -p /data/journal /data/recordings; chown -R "$UID:$UID" /data; \
    if ! [ -x /usr/sbin/mosquitto ]; then \
        apt-get update && apt-get install -y --no-install-recommends mosquitto \
        && rm -rf /var/lib/apt/lists/*; \
    fi
COPY --from=deps /opt/fleet /opt/fleet
COPY --from=project /dist /tmp/dist
RUN /opt/fleet/bin/pip install --no-cache-dir --disable-pip-version-check --no-index --no-deps \
        /tmp/dist/*.whl \
    && rm -rf /tmp/dist
ENV PATH=/opt/fleet/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    MPLBACKEND=Agg
USER fleet
WORKDIR /data
ENTRYPOINT ["fleet"]
CMD ["--help"]
