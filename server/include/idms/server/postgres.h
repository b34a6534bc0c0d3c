// idms-server's state in PostgreSQL (`--store postgres://USER@HOST:PORT/DB`): the model library,
// the session index, browser logins and session ownership leases, in one database several servers
// share. Blobs and recordings stay in --data. See server/README.md, "Several servers: PostgreSQL".
#pragma once

#include <chrono>
#include <memory>
#include <string>

#include "idms/server/auth.h"
#include "idms/server/storage.h"

namespace idms::server {

// The stores that live in PostgreSQL. Each may throw StoreUnavailable while the database is down,
// and reconnects by itself on the next call once it is back.
struct PostgresStores {
  std::unique_ptr<ModelStore> models;
  std::unique_ptr<SessionIndex> sessions;
  std::unique_ptr<LoginSessions> logins;
  std::unique_ptr<LeaseStore> leases;
};

// Connects to `conninfo` (a postgres:// URL or a libpq "key=value" string), applies the schema
// migrations this server knows that the database lacks, and opens the stores on a pool of
// `max_connections`. False with *error when the database cannot be reached, a migration fails,
// or the database's schema is newer than this server's (then nothing is changed).
bool OpenPostgres(const std::string& conninfo, std::chrono::seconds login_lifetime, int max_connections,
                  PostgresStores* stores, std::string* error);

// The migrations alone (tests, tools): the number applied (0: up to date), -1 with *error.
int MigratePostgres(const std::string& conninfo, std::string* error);
// The newest schema version this server knows (its last migration).
int PostgresSchemaVersion();

// Whether `text` names a PostgreSQL database for --store: a postgres:// or postgresql:// URL, or
// a libpq "key=value" connection string.
bool IsPostgresConninfo(const std::string& text);

}  // namespace idms::server
