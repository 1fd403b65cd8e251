#!/bin/sh
# Builds the Go program of scenario guest_go (tests/linux/go/hello.go, the standard library
# only) as a static executable, target/linux/go-hello (run by `cargo xtask test` from the
# workspace root before the image is assembled; the manifest's `debian_packages` installs
# Debian's golang-go first). Nothing is fetched: no module proxy, no toolchain download.
set -eu
if ! command -v go >/dev/null 2>&1; then
    echo "guest_go: no \`go\` in PATH: install Debian's golang-go (apt-get install golang-go)" >&2
    exit 1
fi
mkdir -p target/linux target/go-cache
export CGO_ENABLED=0 GOFLAGS=-mod=mod GOPROXY=off GOTOOLCHAIN=local GO111MODULE=off
export GOCACHE="$PWD/target/go-cache"
go build -trimpath -o target/linux/go-hello tests/linux/go/hello.go
