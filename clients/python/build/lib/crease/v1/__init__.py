"""gRPC stubs of crease.v1, generated from proto/ when the package was built."""
