# walkstream: bake and serve city scenes.  `docker compose up server` uses this image.
FROM python:3.11-slim

# Mesa's EGL and software (llvmpipe) GL: the bake renders visibility headless with moderngl
RUN apt-get update \
    && apt-get install -y --no-install-recommends libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri \
    && rm -rf /var/lib/apt/lists/*

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /app
# only what the package needs (every folder pyproject.toml's package-dir names), so local
# virtualenvs and outputs stay out of the image
COPY pyproject.toml README.md ./
COPY shared ./shared
COPY server ./server
COPY client ./client
COPY benchmarks ./benchmarks
COPY walkstream ./walkstream
RUN pip install . && rm -rf build *.egg-info

VOLUME /data
EXPOSE 8000
ENTRYPOINT ["walkstream"]
CMD ["serve", "/data/city.db", "--host", "0.0.0.0", "--port", "8000"]
